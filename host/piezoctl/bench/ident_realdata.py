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

__all__ = ["CASES", "Case", "run_cases", "speed", "main", "default_data_dir", "options_for"]


@dataclass
class Case:
    """A fit set and a test set of recordings.

    ``test_from_s``: evaluate the test file only from this time [s] (the model
    is still run on the whole file, so its operators see the full history).
    ``fit_until_s``: the fit uses only samples before this time [s].
    ``extra``: identify options of the case (e.g. ``--delay-s``).
    """

    name: str
    fit: list
    test: list
    extra: list = field(default_factory=list)
    fit_until_s: float | None = None
    test_from_s: float = 0.0
    note: str = ""


CASES = [
    Case("valve 20Hz->40Hz", ["valve_20hz_forc.csv"], ["valve_40hz_forc.csv"]),
    Case("valve 40Hz->20Hz", ["valve_40hz_forc.csv"], ["valve_20hz_forc.csv"]),
    Case("valve sweeps->inv_sine50", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_sine50.csv"],
         note="other session: offset differs"),
    Case("valve sweeps->inv_tri50", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_tri50.csv"],
         note="other session: offset differs"),
    Case("valve sweeps->inv_bigsine", ["valve_20hz_forc.csv", "valve_40hz_forc.csv"], ["valve_inverse_bigsine.csv"],
         note="other session: offset differs"),
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


def options_for(kind: str, extra: list) -> Options:
    """The identify options of ``kind`` with their defaults, as the CLI would give them."""
    from ..commands import identify as ident_cmd
    ap = build_parser()
    if kind == "cascade":
        # the real recordings are single runs (sweeps, or one drive each), not
        # the paper's quasi-static + inverse-processed chirp pairs
        extra = [*extra, "--cascade-fallback"]
    args = ap.parse_args(["identify", "--model", kind, "--data", "x.csv", "--out", "x.json", *extra])
    dests = list(ident_cmd.COMMAND_OPTION_DESTS) + ident_cmd._KIND_DESTS.get(kind, [])
    opts = Options({d: getattr(args, d) for d in dests if hasattr(args, d)})
    if opts.get("u_range") is not None:
        opts["u_range"] = list(opts["u_range"])
    return opts


def _evaluate(kind, params, path, t_from):
    rec = load_recording(path)
    y = simulate_model(Model(kind=kind, params=params, provenance={}), rec.t, rec.u, rec.u2)
    m = rec.t >= rec.t[0] + t_from
    e = y[m] - rec.y[m]
    return nrmse(rec.y[m], y[m]), nrmse(rec.y[m], y[m] - e.mean()), float(e.mean())


def run_cases(data_dir: Path, kinds, cases=CASES, tmp: str | None = None):
    """Fit and evaluate every kind on every case.

    Returns
    -------
    list of dict
        One per (kind, case, test file): ``nrmse``, ``nrmse_offset_removed``,
        ``mean_error_um``, ``fit_nrmse`` (mean over fit files), ``fit_time_s``,
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
                    opts = options_for(kind, case.extra)
                    t0 = time.perf_counter()
                    res = identify(kind, fit_paths, opts)
                    dt = time.perf_counter() - t0
                    fit_scores = [d["nrmse"] for d in res["provenance"]["data"]]
                    for name in case.test:
                        n, n_off, mean = _evaluate(kind, res["params"], data_dir / name, case.test_from_s)
                        rows.append({"kind": kind, "case": case.name, "test": name, "nrmse": n,
                                     "nrmse_offset_removed": n_off, "mean_error_um": mean,
                                     "fit_nrmse": float(np.mean(fit_scores)), "fit_time_s": dt})
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
                res = identify(kind, [path], opts)
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
    ap.add_argument("--kinds", nargs="+", default=None, help="kinds to run (default: all that import)")
    ap.add_argument("--speed", action="store_true", help="only time each kind on 30 s of 10 kHz synthetic data")
    ap.add_argument("--markdown", action="store_true", help="print the table as Markdown")
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
    rows = run_cases(args.data, kinds)
    print("NRMSE = RMS(model - measured) / range(measured); inv_* cases: (offset removed) in parentheses")
    print(format_table(rows, markdown=args.markdown))
    return 0


if __name__ == "__main__":
    sys.exit(main())
