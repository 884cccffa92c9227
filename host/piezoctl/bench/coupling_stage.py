"""Cross-coupling benchmark on two-axis data from the C stage model.

``tools/bench-coupling --data stage`` prints the table (``docs/cross-coupling.md``).
The same comparison as :mod:`piezoctl.bench.coupling` (distributed Hammerstein
vs. modified Preisach), but the two-axis data come from the C stage model
(:func:`piezoctl.sil.stage.simulate_stage`, ``firmware/targets/sil/stages/two_axis.json``),
the model the SIL firmware runs against, instead of the Python generator.

Protocol (per frequency f in 1, 10, 35, 100, 130 Hz)
    Axis 1 (the receiving axis) is held at a constant drive; axis 2 is driven
    with the paper's excitation ``4 + 5 sin(2 pi f t)`` V (-1..9 V) mapped onto the
    stage's 0..150 V amplifier range: ``u2 = 75 + A sin(2 pi f t)`` V, A = 70 V
    (5..145 V) unless axis 2 would leave its sensor range (near the 140 Hz
    first mode: A is then reduced by the measured overshoot, see
    :func:`amplitude`). Each record is 6000 samples of two periods (sample
    rate 3000 f, like the Python generator), preceded by a settling segment
    (0.5 s: both drives ramped to their starting value and held) that is cut.
    Axis 1 is held at 9 drive levels 5, 22.5, ..., 145 V (its 9 positions,
    about 0.5..16.5 um); the validation positions are the 8 levels between.

The coupled displacement
    ``y = y1 - y1_base``: axis 1's measured displacement minus the same run
    with axis 2 held at 75 V, with the same noise seed. This removes axis 1's
    own creep and drift (the coupling at 1 Hz, 45 nm, is smaller than the
    creep of a freshly stepped axis over a second) and cancels its sensor
    noise up to the ADC's quantization (0.37 nm): the models see the coupling
    the stage model produces, as a well-averaged measurement would.
    Position x = mean of ``y1_base`` [um] (column ``x2`` of the recordings:
    the stage's coupling into axis 1 depends on axis 1's own position).
    Coupling % = ptp(y) / ptp(y2) over the last period (y2 = axis 2's
    measured displacement).
"""

from __future__ import annotations

import argparse

import numpy as np

from ..ident import hammerstein as ham
from ..ident.common import Options
from ..io.recording import Recording
from ..sil.stage import default_stage_path, simulate_stage, stage_info
from .coupling import error_row, fit_both, last_period_errors, markdown

__all__ = ["STAGE", "FREQS", "LEVELS_V", "BETWEEN_V", "record", "amplitude", "generate", "run", "main"]

STAGE = default_stage_path("two_axis")
FREQS = (1.0, 10.0, 35.0, 100.0, 130.0)
LEVELS_V = np.linspace(5.0, 145.0, 9)           # axis-1 drive levels (its 9 positions)
BETWEEN_V = 0.5 * (LEVELS_V[1:] + LEVELS_V[:-1])
N = 6000
U_MID, U_AMP = 75.0, 70.0
SETTLE_S = 0.5
ADC_SPAN_UM = 24.0                               # two_axis.json: adc range -2..22 um


def record(f: float, level_v: float, *, amp: float = U_AMP, n: int = N, seed: int = 1,
           stage=STAGE) -> dict:
    """One record: axis 1 held at ``level_v``, axis 2 driven ``75 + amp sin(2 pi f t)`` V.

    Returns
    -------
    dict
        ``t`` [s] (n samples, two periods), ``u2`` [V], ``y`` (coupled
        displacement of axis 1 [um]), ``x`` (axis 1's position [um], scalar),
        ``y2`` (axis 2's measured displacement [um]).
    """
    fs = n * f / 2.0
    ns = int(round(SETTLE_S * fs))
    ramp = ns // 2
    t = np.arange(ns + n) / fs
    u1 = np.full(t.size, float(level_v))
    u1[:ramp] = np.linspace(0.0, level_v, ramp)
    u2 = np.full(t.size, U_MID)
    u2[:ramp] = np.linspace(0.0, U_MID, ramp)
    base = u2.copy()
    tt = np.arange(n) / fs
    u2[ns:] = U_MID + amp * np.sin(2 * np.pi * f * tt)
    y1, y2 = simulate_stage(stage, t, u1, u2, seed=seed)
    b1, _ = simulate_stage(stage, t, u1, base, seed=seed)
    return {"t": tt, "u2": u2[ns:], "y": (y1 - b1)[ns:], "x": float(np.mean(b1[ns:])), "y2": y2[ns:]}


def amplitude(f: float, stage=STAGE) -> float:
    """Drive amplitude of axis 2 at f [V]: 70 V, or less where axis 2 would overshoot its sensor range.

    Measured, not computed from the stage file: one record at the middle level;
    if axis 2's peak-to-peak displacement exceeds 90 % of the ADC span, the
    amplitude is scaled to bring it to 60 % of the span.
    """
    r = record(f, LEVELS_V[4], stage=stage)
    span = np.ptp(r["y2"])
    if span <= 0.9 * ADC_SPAN_UM:
        return U_AMP
    r = record(f, LEVELS_V[4], amp=U_AMP / 3.0, stage=stage)  # small enough to stay in range
    return float(min(U_AMP, U_AMP / 3.0 * 0.6 * ADC_SPAN_UM / np.ptp(r["y2"])))


def generate(f: float, levels, amp: float, seed: int = 1, stage=STAGE) -> list[Recording]:
    """Recordings (columns t, u, y, u2, x2) of the coupling at each axis-1 level."""
    recs = []
    for k, lv in enumerate(levels):
        r = record(f, lv, amp=amp, seed=seed * 100 + k, stage=stage)
        recs.append(Recording(t=r["t"], u=np.zeros_like(r["t"]), y=r["y"], u2=r["u2"],
                              x2=np.full(r["t"].size, r["x"]), meta={"y2_ptp": float(np.ptp(r["y2"][r["t"] >= r["t"][-1] - 1.0 / f]))}))
    return recs


def run(settings: dict | None = None, seed: int = 0, verbose: bool = True, freqs=FREQS,
        stage=STAGE) -> dict:
    """Per frequency: fit both models on the 9 training positions, evaluate there and between.

    Returns the same structure as :func:`piezoctl.bench.coupling.run`, plus ``amp_v`` per row.
    """
    if stage_info(stage)[0] != 2:
        raise ValueError(f"{stage}: the coupling benchmark needs a two-axis stage")
    opts = Options({f"hammerstein_{k}": v for k, v in (settings or {}).items()})
    rows = []
    t_h = t_p = 0.0
    hp = None
    for f in freqs:
        amp = amplitude(f, stage)
        recs = generate(f, LEVELS_V, amp, seed * 1000 + 1, stage)
        hp, pp, dt_h, dt_p = fit_both(recs, opts)
        t_h += dt_h
        t_p += dt_p
        row = {"f": f, "amp_v": amp}
        for label, levels in (("train", LEVELS_V), ("between", BETWEEN_V)):
            evals = recs if label == "train" else generate(f, levels, amp, seed * 1000 + 2, stage)
            eh, ep, cp = [], [], []
            for r in evals:
                last, e_h, e_p = last_period_errors(hp, pp, r, f)
                eh.append(e_h)
                ep.append(e_p)
                cp.append(100 * np.ptp(r.y[last]) / r.meta["y2_ptp"])
            row[label] = error_row(eh, ep, cp)
        rows.append(row)
    out = {"rows": rows, "fit_s": {"hammerstein": t_h, "preisach": t_p}, "params": hp}
    if verbose:
        print(markdown(out))
        print("Drive amplitude of axis 2 per frequency: "
              + ", ".join(f"{r['f']:g} Hz {r['amp_v']:.1f} V" for r in rows))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-coupling --data stage", description=__doc__.splitlines()[0])
    ap.add_argument("--refine", type=int, default=ham.DEFAULTS["refine"])
    ap.add_argument("--channels", type=int, default=2)
    ap.add_argument("--m", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stage", default=str(STAGE), help="two-axis stage parameter file")
    ap.add_argument("--freqs", type=float, nargs="+", default=list(FREQS))
    args = ap.parse_args(argv)
    run({"refine": args.refine, "channels": args.channels, "m": args.m}, seed=args.seed,
        freqs=tuple(args.freqs), stage=args.stage)
    return 0
