"""The diagnosis base against hysteresis laws it does not contain (docs/diagnose.md, "Foreign benchmark").

For each law of the foreign stage simulator (``piezoctl.foreign.hysteresis``, written independently of the
base): a 40 um stroke over 0..150 V, 5 nm white noise; calibration = a 2 Hz decaying sine (12 s) and FORC
sweeps (14 reversal levels); the base (``piezoctl.ident.base.fit_base``) is fitted on it and predicts, inside
the calibrated range, nested triangles (60 then 30 V amplitude, 1 Hz) and a random walk. Prints the held-out
RMS error [nm] per law and seed against the noise.

    tools/bench-base [--seeds 0 1] [--laws preisach kp ...]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..foreign.hysteresis import LAWS, draw_law
from ..ident import refined
from ..ident.base import fit_base
from ..io.recording import Recording

__all__ = ["main"]

FS = 10_000.0
STROKE_UM = 40.0
NOISE_UM = 0.005


def _drives(rng):
    t = np.arange(int(12 * FS)) / FS
    cal = [75 + 72 * np.sin(2 * np.pi * 2 * t) * np.exp(-t / 5),
           np.concatenate([np.linspace(3, 147, 4000)] + [np.concatenate([np.linspace(147, lv, 1500),
                                                                           np.linspace(lv, 147, 1500)])
                                                           for lv in np.linspace(10, 140, 14)])]
    tt = np.arange(int(6 * FS)) / FS
    reveal = {"triangles": 75 + np.interp(tt % 1.0, [0, 0.5, 1], [-1, 1, -1]) * np.where(tt < 3, 60, 30),
              "random walk": 75 + 55 * np.sin(np.cumsum(rng.normal(0, 0.004, tt.size)))}
    return cal, reveal


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-base", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=list(LAWS))
    a = ap.parse_args(argv)
    print(f"stroke {STROKE_UM:g} um, noise {1000 * NOISE_UM:g} nm; held-out RMS [nm] inside the calibrated range")
    for name in a.laws:
        for seed in a.seeds:
            law = draw_law(np.random.default_rng(seed), name)

            def stage(u):
                return 0.5 * STROKE_UM * law((u - 75.0) / 75.0)

            rng = np.random.default_rng(1000 + seed)
            cal_u, reveal = _drives(rng)
            cal = [Recording(t=np.arange(u.size) / FS, u=u, y=stage(u) + rng.normal(0, NOISE_UM, u.size))
                   for u in cal_u]
            t0 = time.perf_counter()
            base = fit_base(cal)
            info = base.pop("base_info")["plane"]
            errs = []
            for u in reveal.values():
                e = (refined.simulate(base, np.arange(u.size) / FS, u) - stage(u))[int(0.5 * FS):]
                errs.append(1000 * float(np.sqrt(np.mean(e ** 2))))
            print(f"{name:16s} seed {seed}: plane R{info['plays']} K{info['knots']}"
                  f"{' + Bouc-Wen' if info['bouc_wen'] else ''}: " +
                  ", ".join(f"{k} {v:.1f} nm" for k, v in zip(reveal, errs)) + f" ({time.perf_counter() - t0:.1f} s)",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
