"""``piezoctl fit-tf``: fit a continuous transfer function to a frequency response.

Contract (``docs/dynamics.md``)::

    piezoctl fit-tf (--frf FRF.csv | --data REC.csv) --order N --method {wcls,pso-wcls} --out TF.json
                    [--num-order NB] [--seed S] [--te-target T] [--always-pso] [--no-refine]
                    [--plot FILE.png] [--frf-out FRF.csv] [estimate options of piezoctl frf]

``FRF.csv`` has a header line naming the columns ``f_hz,mag,phase_deg`` (order
free, an optional ``coherence`` column is read, other columns ignored, ``#``
lines skipped, a ``# resolution_hz: R`` line gives the line spacing);
``f_hz`` [Hz] strictly increasing and > 0, ``mag`` > 0, every value finite.
``--data REC.csv`` estimates the FRF from a recording first (``piezoctl frf``,
same options). ``TF.json`` holds ``num`` and ``den`` (descending powers of s,
``den[0] = 1``), ``poles`` as ``[[re, im], ...]`` [rad/s], ``poles_hz`` (each
pole's natural frequency [Hz] and damping), ``resonance_hz``, ``resonances``
(each checked against the data), ``warnings`` and ``te`` (mean relative error).
Any breach of the input contract is one line on stderr and exit status 2.
"""

from __future__ import annotations

import csv
import json
import math

from ..errors import CliError
from ._options import Progress, add_output, emit
from ._outputs import Outputs, check_output_paths
from .frf import ESTIMATE_OPTIONS, add_estimate_options, estimate_from_args, write_frf_csv

FRF_COLUMNS = ("f_hz", "mag", "phase_deg")
FAR_OUT = 10.0
"""A real pole below ``f_min / FAR_OUT`` or above ``FAR_OUT f_max`` of the data is warned about [1]."""


def add_parser(sub) -> None:
    p = sub.add_parser("fit-tf", help="fit a transfer function (WCLS / PSO-WCLS) to a frequency response "
                                      "(FRF.csv, or estimated from a recording)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--frf", metavar="FRF.csv", help="CSV with columns f_hz,mag,phase_deg[,coherence]")
    src.add_argument("--data", metavar="REC.csv",
                     help="recording (t,u,y): estimate its FRF as piezoctl frf does, then fit it")
    p.add_argument("--order", required=True, type=int, help="denominator order n (>= 1)")
    p.add_argument("--num-order", type=int, default=None, help="numerator order (default: n)")
    p.add_argument("--method", choices=("wcls", "pso-wcls"), default="pso-wcls",
                   help="wcls: weighted complex least squares alone (may be unstable); pso-wcls "
                        "(default): WCLS, the particle swarm when unstable, then the output-error "
                        "refinement; always stable")
    p.add_argument("--seed", type=int, default=0, help="PSO random seed (default 0)")
    p.add_argument("--te-target", type=float, default=1e-3, help="PSO stop criterion Te* (default 1e-3)")
    p.add_argument("--always-pso", action="store_true", help="run the swarm even if WCLS is stable")
    p.add_argument("--no-refine", action="store_true",
                   help="pso-wcls: the paper's PSO-WCLS alone, without the output-error refinement "
                        "(for comparison; docs/dynamics.md)")
    p.add_argument("--out", required=True, metavar="TF.json", help="output TF.json")
    p.add_argument("--plot", metavar="FILE.png", help="Bode plot of the data and the fit")
    p.add_argument("--frf-out", metavar="FRF.csv", help="with --data: also write the estimated FRF")
    add_estimate_options(p)
    add_output(p)
    p.set_defaults(func=run)


def load_frf_csv(path: str):
    """Read an FRF CSV (columns ``f_hz,mag,phase_deg``, optional ``coherence``); raise CliError naming the problem.

    Returns
    -------
    piezoctl.ident.frf.FRF
        With ``coherence`` when the column is present and ``resolution_hz`` when a
        ``# resolution_hz: R`` metadata line gives it.
    """
    import numpy as np

    from ..ident.frf import FRF

    try:
        with open(path, newline="", encoding="utf-8") as fh:
            raw = [ln for ln in fh if ln.strip()]
    except OSError as exc:
        raise CliError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise CliError(f"{path}: not a text (UTF-8) file") from None
    resolution = None
    for ln in raw:
        s = ln.strip()
        if s.startswith("#") and s[1:].strip().startswith("resolution_hz:"):
            try:
                resolution = float(s.split(":", 1)[1])
            except ValueError:
                resolution = float("nan")
            if not (math.isfinite(resolution) and resolution > 0):
                raise CliError(f"{path}: metadata resolution_hz {s.split(':', 1)[1].strip()!r} "
                               f"is not a positive number")
    lines = [ln for ln in raw if not ln.lstrip().startswith("#")]
    if not lines:
        raise CliError(f"{path}: empty file (expected header f_hz,mag,phase_deg)")
    rows = list(csv.reader(lines))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in FRF_COLUMNS if c not in header]
    if missing:
        raise CliError(f"{path}: missing column(s) {', '.join(missing)} (header: {','.join(header)})")
    names = FRF_COLUMNS + (("coherence",) if "coherence" in header else ())
    idx = [header.index(c) for c in names]
    data = np.empty((len(rows) - 1, len(names)))
    for k, row in enumerate(rows[1:]):
        for j, i in enumerate(idx):
            try:
                v = float(row[i])
            except (IndexError, ValueError):
                raise CliError(f"{path}: data row {k + 1}: column {names[j]} is not a number") from None
            if not math.isfinite(v):
                raise CliError(f"{path}: data row {k + 1}: column {names[j]} is {v} (must be finite)")
            data[k, j] = v
    f, mag, ph = data[:, 0], data[:, 1], data[:, 2]
    if f.size < 2:
        raise CliError(f"{path}: need at least 2 frequencies, got {f.size}")
    if np.any(f <= 0):
        raise CliError(f"{path}: f_hz must be > 0 (data row {int(np.argmax(f <= 0)) + 1})")
    bad = np.flatnonzero(np.diff(f) <= 0)
    if bad.size:
        raise CliError(f"{path}: f_hz must increase strictly (data row {int(bad[0]) + 2})")
    if np.any(mag <= 0):
        raise CliError(f"{path}: mag must be > 0 (data row {int(np.argmax(mag <= 0)) + 1})")
    coh = None
    if len(names) == 4:
        coh = data[:, 3]
        if np.any((coh < 0) | (coh > 1)):
            raise CliError(f"{path}: coherence must be in 0..1 (data row {int(np.argmax((coh < 0) | (coh > 1))) + 1})")
    return FRF(f, mag, ph, coh, resolution)


def _describe_poles(report: list[dict]) -> str:
    parts = []
    for r in report:
        if r["pair"]:
            parts.append(f"{r['f_hz']:.4g} Hz zeta {r['damping']:.3g}")
        else:
            parts.append(f"{r['f_hz']:.4g} Hz ({'real' if r['damping'] > 0 else 'real, unstable'})")
    return ", ".join(parts) or "none"


def run(args) -> int:
    given = [n for n, d in ESTIMATE_OPTIONS.items() if getattr(args, n) != d]
    if args.frf and (given or args.frf_out):
        opts = [f"--{n.replace('_', '-')}" for n in given] + (["--frf-out"] if args.frf_out else [])
        raise CliError(f"{', '.join(opts)} appl{'ies' if len(opts) == 1 else 'y'} to --data "
                       f"(an FRF estimated from a recording), not to --frf")
    check_output_paths(args.out, args.plot, args.frf_out)
    if args.order < 1:
        raise CliError(f"--order must be >= 1 (got {args.order})")
    if args.no_refine and args.method != "pso-wcls":
        raise CliError("--no-refine applies to --method pso-wcls (wcls has no refinement)")
    if args.num_order is not None and not 0 <= args.num_order <= args.order:
        raise CliError(f"--num-order must be in 0..{args.order} (got {args.num_order})")
    from ..ident import frf as frfmod
    from ..ident import tf

    warnings = []
    if args.data:
        est = estimate_from_args(args, args.data)  # well under 2 s: no progress line
        frf = est.frf()
        gaps = est.gaps()
        warnings += est.warnings()
        source = args.data
    else:
        frf = load_frf_csv(args.frf)
        gaps = frfmod.find_gaps(frf)
        warnings += [f"no data {g.lo_hz:.4g}-{g.hi_hz:.4g} Hz ({g.lines} lines missing); "
                     f"a fitted model is not constrained there" for g in gaps]
        if frf.coherence is not None:
            low = frf.coherence < frfmod.LOW_COHERENCE
            if low.any():
                warnings.append(f"coherence below {frfmod.LOW_COHERENCE:g} on {int(low.sum())} of "
                                f"{low.size} lines; the magnitude there is biased low")
        source = args.frf
    nb = args.order if args.num_order is None else args.num_order
    if 2 * frf.f_hz.size < nb + 1 + args.order:
        raise CliError(f"{source}: {frf.f_hz.size} frequencies cannot determine "
                       f"{nb + 1 + args.order} parameters of an order-{args.order} model")
    opts = {}
    if args.method == "pso-wcls":
        opts = {"seed": args.seed, "te_target": args.te_target, "always": args.always_pso,
                "refine": not args.no_refine}
    with Progress(args, f"fit ({args.method}, order {args.order})"):
        res = tf.fit_tf(frf, args.order, args.method, args.num_order, **opts)
    resonances = frfmod.check_resonances(res.poles, frf, gaps)
    for r in resonances:
        if r["problems"]:
            verdict = "is not supported by the data" if not r["supported"] else "is flagged"
            warnings.append(f"resonance at {r['f_hz']:.4g} Hz (zeta {r['damping']:.3g}) {verdict}: "
                            f"{'; '.join(r['problems'])}")
    lo_hz, hi_hz = float(frf.f_hz[0]), float(frf.f_hz[-1])
    for r in res.to_dict()["poles_hz"]:
        # complex pairs outside the data are flagged by check_resonances; a real pole far out
        # (the refinement bounds poles to a decade beyond the data) is not determined by them
        if not r["pair"] and not lo_hz / FAR_OUT <= r["f_hz"] <= hi_hz * FAR_OUT:
            warnings.append(f"real pole at {r['f_hz']:.4g} Hz is more than a decade outside the data "
                            f"({lo_hz:.4g}-{hi_hz:.4g} Hz): the data do not determine it (a lower --order "
                            f"or --num-order may describe them as well)")
    out = res.to_dict()
    out["order"] = args.order
    out["f_range_hz"] = [float(frf.f_hz[0]), float(frf.f_hz[-1])]
    out["resonances"] = resonances
    out["gaps"] = [g.to_dict() for g in gaps]
    out["warnings"] = warnings
    out["source"] = {"data": args.data} if args.data else {"frf": args.frf}
    if args.data:
        out["source"].update({k: v for k, v in est.summary().items() if k not in ("gaps",)})

    def write_json(path):
        try:
            with open(path, "w", encoding="utf-8") as fh:
                json.dump(out, fh, indent=2)
                fh.write("\n")
        except OSError as exc:
            raise CliError(f"{path}: cannot write: {exc.strerror or exc}") from None

    with Outputs() as files:
        if args.frf_out:
            files.write(args.frf_out, lambda p: write_frf_csv(p, est, args.data))
        files.write(args.out, write_json)
        if args.plot:
            from ..plots import bode
            with Progress(args, "plot"):
                files.write(args.plot, lambda p: bode(
                    p, frf, fit=(res.num, res.den), gaps=gaps, resonances=resonances,
                    title=f"{source}: {args.method} order {args.order}, te {res.te:.3g}"))
    rz = out["resonance_hz"]
    lines = [f"fit-tf: {args.method} order {args.order}: te = {res.te:.4g}, "
             f"{'stable' if res.stable else 'UNSTABLE'}, written to {args.out}",
             f"  poles: {_describe_poles(out['poles_hz'])}",
             f"  resonance_hz: {'none' if rz is None else f'{rz:.5g}'}"]
    lines += [f"warning: {w}" for w in warnings]
    emit(args, {**out, "out": args.out, "plot": args.plot, "frf_out": args.frf_out}, lines)
    return 0
