"""``tools/bench-ident``: identification benchmark on real recordings, and speed.

Prints a table of NRMSE (RMS error / range of y) per model kind and
(fit set -> test set) case on ``../shared/realdata`` (never copied into the
repository), and with ``--speed`` the time to identify each kind from 30 s of
synthetic 10 kHz data. Cases and their handling of the data's peculiarities
are described in ``docs/identification.md``.

Usage: ``tools/bench-ident [--data DIR] [--kinds kp rkp ...] [--speed] [--markdown]``
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..cli import build_parser
from ..commands.identify import identify
from ..commands.simulate import simulate_model
from ..errors import CliError
from ..ident import MODEL_KINDS
from ..ident.common import Options, nrmse
from ..io.modelfile import Model
from ..io.recording import load_recording, save_recording

__all__ = ["CASES", "Case", "VARIANTS", "run_cases", "speed", "main", "default_data_dir", "options_for",
           "residual_breakdown"]


@dataclass
class Case:
    """A fit set and a test set of recordings.

    ``test_from_s``: evaluate the test file only from this time [s] (the model
    is still run on the whole file, so its operators see the full history).
    ``fit_until_s``: the fit uses only samples before this time [s].
    ``extra``: identify options of the case (e.g. ``--delay-s``).
    ``start_v``: the drive [V] before the files' first sample, for the kinds
    that take it (``cascade-joint``: ``--cascade-u-before``); None: unknown.
    """

    name: str
    fit: list
    test: list
    extra: list = field(default_factory=list)
    fit_until_s: float | None = None
    test_from_s: float = 0.0
    note: str = ""
    start_v: float | None = None


# Rows of the table that run a kind with options of its own: label -> (kind, options).
VARIANTS = {"cascade-joint": ("cascade", ["--cascade-joint"])}


CASES = [
    Case("valve 20Hz->40Hz", ["valve_20hz_forc.csv"], ["valve_40hz_forc.csv"], start_v=0.0),
    Case("valve 40Hz->20Hz", ["valve_40hz_forc.csv"], ["valve_20hz_forc.csv"], start_v=0.0),
    Case("valve sweeps->inv_sine50", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_sine50.csv"],
         note="other session: offset differs", start_v=0.0),
    Case("valve sweeps->inv_tri50", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_tri50.csv"],
         note="other session: offset differs", start_v=0.0),
    Case("valve sweeps->inv_bigsine", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_bigsine.csv"],
         note="other session: offset differs", start_v=0.0),
    Case("actuator 3.5-6.5s->6.5-10s", ["actuator_150v_1hz.csv"], ["actuator_150v_1hz.csv"],
         extra=["--skip-s", "3.5"], fit_until_s=6.5, test_from_s=6.5,
         note="step at 3.26 s and ringing skipped"),
    Case("micromanip model->test", ["micromanipulator_1hz_model.csv"], ["micromanipulator_1hz_test.csv"],
         note="as recorded"),
    Case("micromanip model->test, 30ms delay", ["micromanipulator_1hz_model.csv"], ["micromanipulator_1hz_test.csv"],
         extra=["--delay-s", "0.03", "--skip-s", "0.1"],
         note="30 ms input delay; start transient skipped in the fit"),
]


def default_data_dir() -> Path:
    """``../shared/realdata`` beside the repository."""
    return Path(__file__).resolve().parents[3] / ".." / "shared" / "realdata"


def options_for(kind: str, extra: list, start_v: float | None = None) -> Options:
    """The identify options of ``kind`` (or a :data:`VARIANTS` label) with their defaults, as the CLI
    would give them; ``start_v``: the case's drive before the first sample, for the kinds that take it."""
    from ..commands import identify as ident_cmd
    ap = build_parser()
    if kind in VARIANTS:
        kind, more = VARIANTS[kind]
        extra = [*extra, *more]
        if start_v is not None:
            extra = [*extra, "--cascade-u-before", repr(float(start_v))]
    if kind == "cascade" and "--cascade-joint" not in extra:
        # the real recordings are single runs (sweeps, or one drive each), not
        # the paper's quasi-static + inverse-processed chirp pairs
        extra = [*extra, "--cascade-fallback"]
    args = ap.parse_args(["identify", "--model", kind, "--data", "x.csv", "--out", "x.json", *extra])
    dests = list(ident_cmd.COMMAND_OPTION_DESTS) + ident_cmd._KIND_DESTS.get(kind, [])
    opts = Options({d: getattr(args, d) for d in dests if hasattr(args, d)})
    if opts.get("u_range") is not None:
        opts["u_range"] = list(opts["u_range"])
    return opts


def _evaluate(kind, params, path, t_from, breakdown=False):
    rec = load_recording(path)
    y = simulate_model(Model(kind=kind, params=params, provenance={}), rec.t, rec.u, rec.u2)
    m = rec.t >= rec.t[0] + t_from
    e = y[m] - rec.y[m]
    out = (nrmse(rec.y[m], y[m]), nrmse(rec.y[m], y[m] - e.mean()), float(e.mean()))
    return (*out, residual_breakdown(rec.t[m], rec.u[m], rec.y[m], y[m])) if breakdown else out


def residual_breakdown(t, u, y, y_model, startup_s: float = 0.1) -> dict:
    """Where the test error lies, as parts of the NRMSE whose squares add up to its square.

    Parameters
    ----------
    t, u, y, y_model : ndarray, shape (T,)
        Times [s], drive [V], measured and modelled output [um].
    startup_s : float
        The first ``startup_s`` [s] count as the start-up.

    Returns
    -------
    dict
        ``total``; ``startup`` (t < startup_s), ``hold`` (the rest before the
        drive first moves), ``sweep_harmonics`` (after it: the error's power
        at multiples of the drive's fundamental, +-1 FFT line) and
        ``sweep_other`` (the rest of the sweep's error power); ``noise``: the
        measurement noise's share, from the hold's sample-to-sample
        differences (std / sqrt 2), as if it were on every sample;
        ``fundamental_hz``.
    """
    from ..ident.cascade_joint import fundamental_hz
    t, u, y, ym = (np.asarray(a, float) for a in (t, u, y, y_model))
    e = ym - y
    n, span = e.size, float(np.ptp(y))
    moved = np.flatnonzero(np.abs(u - u[0]) > 1e-6 * max(np.ptp(u), 1e-12))
    i_move = int(moved[0]) if moved.size else n
    i_start = int(np.searchsorted(t - t[0], startup_s))
    part = {"startup": e[:min(i_start, i_move)], "hold": e[min(i_start, i_move):i_move]}
    sw = e[i_move:]
    f0 = fundamental_hz(t[i_move:], u[i_move:]) if sw.size > 4 else 0.0
    harm = 0.0
    if sw.size > 4 and f0 > 0:
        E = np.fft.rfft(sw)
        f = np.fft.rfftfreq(sw.size, float(np.median(np.diff(t))))
        p = np.abs(E) ** 2 * 2 / sw.size      # one-sided: sum(p) ~ sum(sw**2)
        p[0] /= 2
        k = np.rint(f / f0)
        near = (k >= 1) & (np.abs(f - k * f0) <= 1.01 * (f[1] - f[0]))
        harm = float(np.sum(p[near]) / np.sum(p) * np.sum(sw ** 2)) if np.sum(p) > 0 else 0.0
    out = {k: float(np.sqrt(np.sum(v ** 2) / n) / span) for k, v in part.items()}
    out["sweep_harmonics"] = float(np.sqrt(harm / n) / span)
    out["sweep_other"] = float(np.sqrt(max(float(np.sum(sw ** 2)) - harm, 0.0) / n) / span)
    hold_y = y[min(i_start, i_move):i_move]
    out["noise"] = float(np.std(np.diff(hold_y)) / np.sqrt(2) / span) if hold_y.size > 10 else float("nan")
    out["total"] = float(np.sqrt(np.mean(e ** 2)) / span)
    out["fundamental_hz"] = f0
    return out


def run_cases(data_dir: Path, kinds, cases=CASES, tmp: str | None = None, breakdown: bool = False):
    """Fit and evaluate every kind on every case.

    Returns
    -------
    list of dict
        One per (kind, case, test file): ``nrmse``, ``nrmse_offset_removed``,
        ``mean_error_um``, ``fit_nrmse`` (mean over fit files), ``fit_time_s``,
        with ``breakdown`` also ``residual`` (:func:`residual_breakdown`),
        or ``error`` when the kind failed.
    """
    rows = []
    with tempfile.TemporaryDirectory(dir=tmp) as td:
        for case in cases:
            fit_paths = []
            for name in case.fit:
                p = str(data_dir / name)
                if case.fit_until_s is not None:
                    rec = load_recording(p)
                    keep = rec.t < case.fit_until_s
                    p = os.path.join(td, f"fitpart_{name}")
                    save_recording(p, {"t": rec.t[keep], "u": rec.u[keep], "y": rec.y[keep]}, meta=rec.meta)
                fit_paths.append(p)
            for kind in kinds:
                try:
                    opts = options_for(kind, case.extra, case.start_v)
                    base = VARIANTS[kind][0] if kind in VARIANTS else kind
                    t0 = time.perf_counter()
                    res = identify(base, fit_paths, opts)
                    dt = time.perf_counter() - t0
                    fit_scores = [d["nrmse"] for d in res["provenance"]["data"]]
                    for name in case.test:
                        got = _evaluate(base, res["params"], data_dir / name, case.test_from_s, breakdown)
                        rows.append({"kind": kind, "case": case.name, "test": name, "nrmse": got[0],
                                     "nrmse_offset_removed": got[1], "mean_error_um": got[2],
                                     "fit_nrmse": float(np.mean(fit_scores)), "fit_time_s": dt,
                                     **({"residual": got[3]} if breakdown else {})})
                except (CliError, ValueError, np.linalg.LinAlgError) as exc:
                    rows.append({"kind": kind, "case": case.name, "error": f"{type(exc).__name__}: {exc}"})
    return rows


def synthetic_30s(path: str, seconds: float = 30.0, rate_hz: float = 10_000.0, seed: int = 0) -> None:
    """Write a synthetic 10 kHz recording: multi-tone drive, hysteretic output, noise."""
    from ..models.play import play_outputs
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    env = 0.6 + 0.4 * np.sin(2 * np.pi * 0.13 * t)
    v = env * (0.7 * np.sin(2 * np.pi * 1.0 * t) + 0.3 * np.sin(2 * np.pi * 7.3 * t + 1.0))
    v /= np.max(np.abs(v))
    r = 0.9 * np.arange(8) / 8
    y = 10.0 * v + play_outputs(v, r) @ np.linspace(2.0, 0.2, 8) + 0.5 * v ** 3
    y += 0.01 * rng.standard_normal(t.size)
    save_recording(path, {"t": t, "u": 75.0 + 75.0 * v, "y": y}, meta={"sample_rate_hz": rate_hz})


def speed(kinds, tmp: str | None = None):
    """Time to identify each kind from 30 s of 10 kHz synthetic data (load + fit + metrics).

    Returns ``{kind: (wall_s, cpu_s, fit_nrmse, error)}``; CPU time is this
    process's (the machine is shared, so wall time depends on the load).
    """
    out = {}
    with tempfile.TemporaryDirectory(dir=tmp) as td:
        path = os.path.join(td, "synthetic_30s_10khz.csv")
        synthetic_30s(path)
        for kind in kinds:
            opts = options_for(kind, [])
            t0 = time.perf_counter()
            c0 = time.process_time()
            try:
                res = identify(VARIANTS[kind][0] if kind in VARIANTS else kind, [path], opts)
                out[kind] = (time.perf_counter() - t0, time.process_time() - c0,
                             res["provenance"]["data"][0]["nrmse"], None)
            except (CliError, ValueError) as exc:
                out[kind] = (None, None, None, str(exc))
    return out


def available_kinds():
    """Kinds whose module imports (cascade/hammerstein are written elsewhere)."""
    import importlib
    ok = []
    for kind, mod in MODEL_KINDS.items():
        try:
            importlib.import_module(mod)
            ok.append(kind)
        except Exception:
            pass
    return ok


def format_table(rows, markdown: bool = False) -> str:
    """Table model x case of NRMSE; cross-session cases also with the offset removed."""
    cases = []
    for r in rows:
        key = (r["case"], r.get("test"))
        if r.get("test") is not None and key not in cases:
            cases.append(key)
    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    cell = {(r["kind"], r["case"], r.get("test")): r for r in rows}
    errs = [r for r in rows if "error" in r]
    head = ["model"] + [c for c, _ in cases]
    lines = []
    body = []
    for k in kinds:
        row = [k]
        for c, t in cases:
            r = cell.get((k, c, t))
            if r is None:
                row.append("failed" if any(e["kind"] == k and e["case"] == c for e in errs) else "-")
            elif "inv_" in c:
                row.append(f"{r['nrmse']:.4f} ({r['nrmse_offset_removed']:.4f})")
            else:
                row.append(f"{r['nrmse']:.4f}")
        body.append(row)
    if markdown:
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "---|" * len(head))
        lines += ["| " + " | ".join(r) + " |" for r in body]
    else:
        w = [max(len(x[i]) for x in [head] + body) for i in range(len(head))]
        lines.append("  ".join(h.ljust(w[i]) for i, h in enumerate(head)))
        lines += ["  ".join(x.ljust(w[i]) for i, x in enumerate(r)) for r in body]
    seen = set()
    for e in errs:
        if (e["kind"], e["error"]) not in seen:
            seen.add((e["kind"], e["error"]))
            lines.append(f"{e['kind']} failed ({e['case']}" + (", and others" if sum(
                1 for x in errs if x["kind"] == e["kind"] and x["error"] == e["error"]) > 1 else "")
                + f"): {e['error']}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-ident", description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir(), help="real recordings directory")
    ap.add_argument("--kinds", nargs="+", default=None,
                    help="kinds to run (default: all that import), or variants: " + ", ".join(VARIANTS))
    ap.add_argument("--cases", nargs="+", default=None, metavar="NAME",
                    help="only the cases whose name starts with one of these (e.g. 'valve 20' 'valve 40')")
    ap.add_argument("--speed", action="store_true", help="only time each kind on 30 s of 10 kHz synthetic data")
    ap.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    ap.add_argument("--residual", action="store_true",
                    help="also print where each test error lies: start-up, hold, the sweep's harmonics, "
                         "the rest, and the noise floor (parts of the NRMSE)")
    args = ap.parse_args(argv)
    kinds = args.kinds or available_kinds()
    if args.speed:
        print("identify time, 30 s of 10 kHz synthetic data (300000 samples; load + fit + NRMSE):")
        for kind, (sec, cpu, score, err) in speed(kinds).items():
            print(f"  {kind:12s} " + (f"wall {sec:6.2f} s  cpu {cpu:6.2f} s   fit NRMSE {score:.4f}"
                                      if err is None else f"failed: {err}"))
        return 0
    if not args.data.is_dir():
        print(f"bench-ident: no real recordings at {args.data}", file=sys.stderr)
        return 2
    cases = CASES if not args.cases else [c for c in CASES if any(c.name.startswith(x) for x in args.cases)]
    if not cases:
        print(f"bench-ident: no case starts with {args.cases}", file=sys.stderr)
        return 2
    rows = run_cases(args.data, kinds, cases, breakdown=args.residual)
    print("NRMSE = RMS(model - measured) / range(measured); inv_* cases: (offset removed) in parentheses")
    print(format_table(rows, markdown=args.markdown))
    if args.residual:
        print("\nwhere the test error lies (parts of the NRMSE; their squares add up to the total's square):")
        print(f"  {'model':14s} {'case':34s} total   start-up hold    harmonics other   (noise floor)")
        for r in rows:
            b = r.get("residual")
            if b:
                print(f"  {r['kind']:14s} {r['case']:34s} {b['total']:.4f}  {b['startup']:.4f}   {b['hold']:.4f}  "
                      f"{b['sweep_harmonics']:.4f}    {b['sweep_other']:.4f}  ({b['noise']:.5f}; "
                      f"fundamental {b['fundamental_hz']:.1f} Hz)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
