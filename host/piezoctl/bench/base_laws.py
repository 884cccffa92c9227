"""The diagnosis base against hysteresis laws it does not contain (docs/diagnose.md, "Foreign benchmark").

For each law of the foreign stage simulator (``piezoctl.foreign.hysteresis``, written independently of the
base): a 40 um stroke over 0..150 V, 5 nm white noise; calibration = a 2 Hz decaying sine (12 s) and FORC
sweeps (14 reversal levels); the base (``piezoctl.ident.base.fit_base``) is fitted on it and predicts, inside
the calibrated range, nested triangles (60 then 30 V amplitude, 1 Hz) and a random walk. Prints the held-out
RMS error [nm] per law and seed against the noise, and each fit's CPU time and the peak resident memory.

``--nulls SEED``: instead, the null cases of the foreign diagnosis benchmark (``piezoctl.foreign.cases``,
``--n`` cases of the seed, ``--cases`` a subset): the base fitted on each case's calibration as ``diagnose`` fits
it, and its error on each reveal recording against the stage's noise-free output, after the 0.5 s settling and
inside the calibrated drive range, as RMS [nm] and as a multiple of the case's sensor noise (the goal: 2).

    tools/bench-base [--seeds 0 1] [--laws preisach kp ...]
    tools/bench-base --nulls 107 --n 12
"""

from __future__ import annotations

import argparse
import copy
import os
import resource
import tempfile
import time
import zlib

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


def _noise_free(case) -> list:
    """The reveal recordings' noise-free sensor output [um] (the stage's displacement through the sensor's gain,
    offset and curve), drawn as ``write_case`` draws the measured ones (same generator, noise scaled to 0)."""
    from ..foreign.stage import FS_HZ
    st = copy.deepcopy(case.stage)
    st.sensor.noise_um = 0.0
    rng = np.random.default_rng([0, zlib.crc32(case.case_id.encode())])
    out = []
    for group in (case.calibration, case.reveal):
        for r in group:
            n = r.u.size
            if r.warmup_s > 0:
                reps = int(np.ceil(r.warmup_s * FS_HZ / n)) + 1
                y = st.run(np.tile(r.u, reps), None if r.u2 is None else np.tile(r.u2, reps),
                           r.t_session - (reps - 1) * n / FS_HZ, r.session, r.pre_s, rng)[-n:]
            else:
                y = st.run(r.u, r.u2, r.t_session, r.session, r.pre_s, rng)
            if group is case.reveal:
                out.append(y)
    return out


def null_cases(seed: int, n: int, cases=None, settle_s: float = 0.5) -> list:
    """The base's held-out error on the reveal recordings of the null cases of a foreign seed.

    Returns
    -------
    list of dict
        Per case: ``id``, ``law``, ``noise_nm`` (sensor noise), ``plane`` (the chosen size), ``cpu_s`` (the
        fit's CPU time), ``reversal_levels`` and ``plays_allowed`` (what the calibration resolves), ``rows``
        per reveal recording: ``name``, ``rms_nm`` (model minus the noise-free output, settled samples
        inside the calibrated drive range), ``ratio`` (over the noise), ``shape_nm`` (the same without its mean:
        what is left once a level - the recording's unknown initial state, an offset - is taken out), ``inside``
        (fraction of the settled samples scored).
    """
    from ..foreign.cases import case_plan, draw_case, write_case
    from ..io.recording import load_recording
    out = []
    for i, truth in enumerate(case_plan(n)):
        if truth or (cases is not None and i not in cases):
            continue
        case = draw_case(seed, i, truth)
        with tempfile.TemporaryDirectory(prefix="bench-base-") as d:
            files = write_case(case, d)
            cal = [load_recording(p) for p in files["calibration"]]
            rev = [load_recording(p) for p in files["recordings"]]
        c0 = time.process_time()
        base = fit_base(cal, settle_s=settle_s, holdout=True)
        cpu = time.process_time() - c0
        info = base.pop("base_info")["plane"]
        base.pop("_holdout", None)
        k0s = [int(round(settle_s * r.sample_rate_hz)) for r in cal]
        lo = min(float(np.min(r.u[k:])) for r, k in zip(cal, k0s))
        hi = max(float(np.max(r.u[k:])) for r, k in zip(cal, k0s))
        rows = []
        for r, name, y0 in zip(rev, files["recordings"], _noise_free(case)):
            k = int(round(settle_s * r.sample_rate_hz))
            e = (refined.simulate(base, r.t, r.u, r.u2) - y0)[k:]
            m = (r.u[k:] >= lo) & (r.u[k:] <= hi)
            rms = 1000 * float(np.sqrt(np.mean(e[m] ** 2))) if m.any() else float("nan")
            shape = 1000 * float(np.std(e[m])) if m.any() else float("nan")
            rows.append({"name": os.path.basename(name), "rms_nm": rms, "shape_nm": shape,
                         "ratio": rms / (1000 * case.stage.sensor.noise_um), "inside": float(m.mean())})
        out.append({"id": case.case_id, "law": case.stage.law.name, "noise_nm": 1000 * case.stage.sensor.noise_um,
                    "plane": f"R{info['plays']} K{info['knots']}" + (
                        f" + Bouc-Wen n={info['bouc_wen'][2] if len(info['bouc_wen']) > 2 else 1:.2f}"
                        if info["bouc_wen"] else ""),
                    "reversal_levels": int(info["reversal_levels"]), "plays_allowed": list(info["plays_allowed"]),
                    "cpu_s": cpu, "rows": rows})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-base", description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=list(LAWS))
    ap.add_argument("--nulls", type=int, default=None, metavar="SEED",
                    help="the null cases of this foreign benchmark seed instead of the laws alone")
    ap.add_argument("--n", type=int, default=12, help="with --nulls: the seed's case count (its plan)")
    ap.add_argument("--cases", default=None, help="with --nulls: comma list of case indices")
    a = ap.parse_args(argv)
    if a.nulls is not None:
        cases = None if a.cases is None else {int(x) for x in a.cases.split(",")}
        print(f"foreign seed {a.nulls} (n {a.n}) nulls: base error on the reveal [nm] against the noise-free output, "
              "settled, inside the calibrated range (x noise)", flush=True)
        for c in null_cases(a.nulls, a.n, cases):
            print(f"{c['id']:24s} {c['law']:16s} noise {c['noise_nm']:.1f} nm, {c['plane']}, fit {c['cpu_s']:.1f} s "
                  f"CPU; peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB", flush=True)
            # round 13: fewer than 2 R reversal levels leave the plane's thresholds above R unidentified
            print(f"    calibration: {c['reversal_levels']} distinct reversal levels, plays allowed "
                  f"{c['plays_allowed']}" + (" - the plane (minor loops) is not identified, only the reversible "
                                             "curve and the column" if max(c['plays_allowed']) == 1 else ""),
                  flush=True)
            for r in c["rows"]:
                print(f"    {r['name']:36s} {r['rms_nm']:8.1f} nm  x{r['ratio']:6.1f}; without its mean "
                      f"{r['shape_nm']:8.1f} nm  x{r['shape_nm'] / c['noise_nm']:6.1f}  (inside {r['inside']:.2f})",
                      flush=True)
        return 0
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
            t0, c0 = time.perf_counter(), time.process_time()
            base = fit_base(cal)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            info = base.pop("base_info")["plane"]
            errs = []
            for u in reveal.values():
                e = (refined.simulate(base, np.arange(u.size) / FS, u) - stage(u))[int(0.5 * FS):]
                errs.append(1000 * float(np.sqrt(np.mean(e ** 2))))
            bw = info["bouc_wen"]
            print(f"{name:16s} seed {seed}: plane R{info['plays']} K{info['knots']}"
                  f"{f' + Bouc-Wen n={bw[2] if len(bw) > 2 else 1:.2f}' if bw else ''}: " +
                  ", ".join(f"{k} {v:.1f} nm" for k, v in zip(reveal, errs)) +
                  f" (fit {wall:.1f} s wall, {cpu:.1f} s CPU; peak RSS "
                  f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
