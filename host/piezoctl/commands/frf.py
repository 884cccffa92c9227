"""``piezoctl frf``: the frequency response of a recording (Welch H1) with its coherence.

Contract (``docs/dynamics.md``, "piezoctl frf")::

    piezoctl frf --data REC.csv --out FRF.csv [--plot FILE.png]
                 [--nperseg N] [--fmin HZ] [--fmax HZ] [--coherence-min C] [--power-min P]
                 [--json] [--quiet]

``REC.csv`` is a recording (``docs/recordings.md``: columns ``t,u,y``; ``t`` a
uniform grid to 1 % of a period). ``FRF.csv`` is what ``fit-tf --frf`` reads:
``# key: value`` metadata lines, the header ``f_hz,mag,phase_deg,coherence`` and
one row per used line. Gaps (bands without data) and low coherence are
reported as warnings, in the text and in the JSON (``warnings``).

The estimate options and their parsing are shared with ``fit-tf --data``
(:func:`add_estimate_options`, :func:`estimate_from_args`).
"""

from __future__ import annotations

from ..errors import CliError
from ._options import Progress, add_output, emit
from ._outputs import Outputs, check_output_paths

__all__ = ["add_parser", "run", "add_estimate_options", "estimate_from_args", "write_frf_csv",
           "ESTIMATE_OPTIONS"]

# option dest -> default; None means "the estimator's default"
ESTIMATE_OPTIONS = {"nperseg": None, "fmin": None, "fmax": None, "coherence_min": None, "power_min": None}
COHERENCE_MIN = 0.0
POWER_MIN = 1e-4


def add_estimate_options(p) -> None:
    """The H1 estimate's options (``frf``, ``fit-tf --data``); all default to None."""
    g = p.add_argument_group("frequency response estimate (Welch H1)")
    g.add_argument("--nperseg", type=int, metavar="N",
                   help="segment length [samples]; line spacing = rate / N (default: samples / 8, "
                        "15 half-overlapping averages; with --fmin: the power of two >= 8 rate / fmin)")
    g.add_argument("--fmin", type=float, metavar="HZ", help="lowest frequency kept [Hz] (default: first line)")
    g.add_argument("--fmax", type=float, metavar="HZ", help="highest frequency kept [Hz] (default: Nyquist)")
    g.add_argument("--coherence-min", type=float, metavar="C",
                   help=f"drop lines with a lower coherence, 0..1 (default {COHERENCE_MIN:g}: keep all; "
                        f"below 0.8 is reported)")
    g.add_argument("--power-min", type=float, metavar="P",
                   help=f"drop lines whose input power is below P times the in-band maximum "
                        f"(default {POWER_MIN:g}: lines the input does not excite)")


def _check_estimate_args(args) -> None:
    if args.nperseg is not None and args.nperseg < 16:
        raise CliError(f"--nperseg must be >= 16 (got {args.nperseg})")
    for name in ("fmin", "fmax"):
        v = getattr(args, name)
        if v is not None and not (v > 0 and v != float("inf")):
            raise CliError(f"--{name} must be a positive frequency [Hz] (got {v})")
    if args.fmin is not None and args.fmax is not None and args.fmin >= args.fmax:
        raise CliError(f"--fmin {args.fmin:g} must be below --fmax {args.fmax:g}")
    if args.coherence_min is not None and not 0.0 <= args.coherence_min <= 1.0:
        raise CliError(f"--coherence-min must be in 0..1 (got {args.coherence_min})")
    if args.power_min is not None and not 0.0 <= args.power_min < 1.0:
        raise CliError(f"--power-min must be in [0, 1) (got {args.power_min})")


def estimate_from_args(args, path: str):
    """Load the recording ``path`` and estimate its FRF with the command's options.

    Returns
    -------
    piezoctl.ident.frf.FRFEstimate
    """
    _check_estimate_args(args)
    from ..ident import frf as frfmod
    from ..io.recording import load_recording

    rec = load_recording(path)
    if args.fmax is not None and len(rec) > 1 and args.fmax > 0.5 / rec.dt * 1.0001:
        raise CliError(f"--fmax {args.fmax:g} Hz is above the Nyquist frequency {0.5 / rec.dt:.6g} Hz of {path}")
    try:
        return frfmod.estimate(rec.t, rec.u, rec.y, nperseg=args.nperseg, fmin=args.fmin, fmax=args.fmax,
                               coherence_min=COHERENCE_MIN if args.coherence_min is None else args.coherence_min,
                               power_min=POWER_MIN if args.power_min is None else args.power_min)
    except ValueError as exc:
        raise CliError(f"{path}: {exc}") from None


def write_frf_csv(path: str, est, source: str) -> None:
    """Write the used lines of an estimate as FRF.csv (``docs/dynamics.md``)."""
    from ..io.recording import write_csv

    f = est.frf()
    gaps = "; ".join(f"{g.lo_hz:.6g}-{g.hi_hz:.6g}" for g in est.gaps()) or "none"
    meta = {"source": "piezoctl frf", "data": source.replace("\n", " "),
            "estimator": "H1 = Puy/Puu, Welch, Hann window, 50 % overlap",
            "sample_rate_hz": f"{est.sample_rate_hz:.10g}", "resolution_hz": f"{est.resolution_hz:.10g}",
            "nperseg": est.nperseg, "segments": est.segments,
            "power_min": f"{est.power_min:g}", "coherence_min": f"{est.coherence_min:g}", "gaps_hz": gaps}
    write_csv(path, {"f_hz": f.f_hz, "mag": f.mag, "phase_deg": f.phase_deg, "coherence": f.coherence},
              meta=meta, precision=12)


def add_parser(sub) -> None:
    p = sub.add_parser("frf", help="estimate the frequency response of a recording (H1, coherence) into FRF.csv",
                       description="Estimate the frequency response from u to y of a recording (Welch H1) "
                                   "with its coherence, write it as FRF.csv (the format fit-tf --frf reads) "
                                   "and warn about bands without data and low coherence.")
    p.add_argument("--data", required=True, metavar="REC.csv", help="recording with columns t,u,y")
    p.add_argument("--out", required=True, metavar="FRF.csv",
                   help="output: columns f_hz,mag,phase_deg,coherence, one row per used line")
    p.add_argument("--plot", metavar="FILE.png", help="also draw a Bode plot with the coherence")
    add_estimate_options(p)
    add_output(p)
    p.set_defaults(func=run)


def summary_lines(est, path: str) -> list[str]:
    s = est.summary()
    return [f"{path}: {s['used_lines']} of {s['lines']} lines used, {s['f_range_hz'][0]:.4g}-"
            f"{s['f_range_hz'][1]:.4g} Hz, resolution {s['resolution_hz']:.4g} Hz, {s['segments']} averages, "
            f"coherence median {s['coherence_median']:.3f}"]


def run(args) -> int:
    check_output_paths(args.out, args.plot)
    est = estimate_from_args(args, args.data)  # well under 2 s: no progress line
    with Outputs() as out:
        out.write(args.out, lambda p: write_frf_csv(p, est, args.data))
        if args.plot:
            from ..plots import bode
            with Progress(args, "plot"):
                out.write(args.plot, lambda p: bode(p, est.frf(), gaps=est.gaps(), title=f"{args.data}: H1 estimate"))
    warnings = est.warnings()
    result = {"data": args.data, "out": args.out, "plot": args.plot, **est.summary(), "warnings": warnings}
    lines = summary_lines(est, args.data) + [f"written to {args.out}" + (f", plot {args.plot}" if args.plot else "")]
    lines += [f"warning: {w}" for w in warnings]
    emit(args, result, lines)
    return 0
