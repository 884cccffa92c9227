"""``piezoctl diagnose``: locate and name the physics a simulation leaves out (docs/diagnose.md).

``--calibration`` recordings fit the base model (hysteresis plus linear dynamics);
``--recordings`` are the data it does not match. Writes ``DIR/diagnosis.json``,
``DIR/base_model.json``, ``DIR/refined_model.json`` (kind ``refined``; both run
with ``piezoctl simulate --model``) and ``DIR/report.html``.
"""

from __future__ import annotations

from ..errors import CliError

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    p = sub.add_parser("diagnose", help="locate a model/data mismatch, name the missing physics, model it",
                       description="Fit a base model (hysteresis + linear dynamics) on calibration recordings, "
                                   "find where it fails on further recordings, name the physics left out, add "
                                   "it and show the held-out improvement (docs/diagnose.md).")
    p.add_argument("--calibration", required=True, nargs="+", metavar="C.csv", help="calibration recordings")
    p.add_argument("--recordings", required=True, nargs="+", metavar="R.csv",
                   help="recordings the simulation does not match")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--settle-s", type=float, default=0.5, metavar="S",
                   help="seconds at the start of every recording left out of fits and scores (default 0.5)")
    p.add_argument("--max-terms", type=int, default=4, metavar="N", help="at most N added terms (default 4)")
    p.add_argument("--no-report", action="store_true", help="skip report.html")
    p.add_argument("--png", action="store_true", help="also write the report's figures as DIR/plots/*.png")
    p.add_argument("--quiet", action="store_true", help="print only the result")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..diagnose.run import diagnose
    if args.settle_s < 0:
        raise CliError(f"--settle-s {args.settle_s:g}: must be >= 0")
    if args.max_terms < 0:
        raise CliError(f"--max-terms {args.max_terms}: must be >= 0")
    doc = diagnose(args.calibration, args.recordings, args.out, settle_s=args.settle_s, max_terms=args.max_terms,
                   report=not args.no_report, png=args.png, log=(lambda *a, **k: None) if args.quiet else print)
    fit = doc["fit"]
    print(f"named: {', '.join(doc['named'])}")
    print(f"NRMSE base {fit['base']['nrmse']:.4f} -> refined {fit['refined']['nrmse']:.4f} "
          f"(held-out {fit['heldout']['base_nrmse']:.4f} -> {fit['heldout']['refined_nrmse']:.4f})")
    print(f"written: {args.out}/diagnosis.json ({doc['time_s']:.1f} s)")
    return 0
