"""``piezoctl stage simulate``: run the C stage model on a drive recording.

Reads a CSV in the project's recording format (``# key: value`` lines, a
header, one row per sample) with columns ``t`` [s] and ``u`` [V] (and ``u2``
for a two-axis stage), and writes ``t,y[,y2]`` [um] with 17 significant
digits, so the file reads back to the same doubles. Prints one line naming
the file, or with ``--json`` ``{"out", "samples", "axes", "stage", "seed"}``.
"""

from __future__ import annotations

from ..errors import CliError
from ._options import Progress, add_output, emit


def add_parser(sub) -> None:
    p = sub.add_parser("stage", help="the simulated stage (C stage model of the SIL build)")
    ssub = p.add_subparsers(dest="stage_command", metavar="STAGE_COMMAND", required=True)
    s = ssub.add_parser("simulate", help="measured displacement of a stage for a drive recording")
    s.add_argument("--stage", metavar="PARAMS.json",
                   help="stage parameter file (JSON, docs/stage-model.md); "
                        "default: firmware/targets/sil/stages/default.json")
    s.add_argument("--input", required=True, help="CSV with columns t [s], u [V] (and u2)")
    s.add_argument("--out", required=True, help="CSV to write: t,y[,y2] [um]")
    s.add_argument("--seed", type=int, default=1, help="noise seed (default: %(default)s)")
    add_output(s)
    s.set_defaults(func=run)


def read_drive_csv(path: str) -> dict:
    """The drive columns t [s], u [V] (and u2 [V]) of a recording-format CSV.

    Read by :func:`piezoctl.io.recording.load_recording` (``y`` not required),
    so a drive gets the recordings' checks: numbers, finite, time increasing,
    non-physical values refused naming file, line and column.
    """
    from ..io.recording import load_recording
    rec = load_recording(path, require=("t", "u"))
    cols = {"t": rec.t, "u": rec.u}
    if rec.u2 is not None:
        cols["u2"] = rec.u2
    return cols


def run(args) -> int:
    from ..sil import stage as sil_stage  # here: the start-up imports no numpy
    if args.stage is None:
        args.stage = str(sil_stage.default_stage_path())
    cols = read_drive_csv(args.input)
    axes, fs = sil_stage.stage_info(args.stage)
    u2 = cols.get("u2") if axes == 2 else None
    if axes == 1 and "u2" in cols:
        raise CliError(f"{args.input}: column u2 given, but {args.stage} is a one-axis stage")
    try:
        with Progress(args, f"simulating {cols['t'].size} samples"):
            out = sil_stage.simulate_stage(args.stage, cols["t"], cols["u"], u2, seed=args.seed)
    except ValueError as exc:
        if isinstance(exc, CliError):
            raise
        raise CliError(f"{args.input}: {exc}") from exc
    ys = list(out) if axes == 2 else [out]
    header = "t,y,y2" if axes == 2 else "t,y"
    with open(args.out, "w", encoding="utf-8") as fh:
        fh.write(f"# stage: {args.stage}\n# seed: {args.seed}\n# y: measured displacement [um]\n")
        fh.write(header + "\n")
        for k in range(cols["t"].size):
            fh.write(",".join([repr(float(cols["t"][k]))] + [f"{y[k]:.17g}" for y in ys]) + "\n")
    emit(args, {"out": args.out, "samples": int(cols["t"].size), "axes": axes, "stage": args.stage,
                "seed": args.seed},
         f"{args.out}: {cols['t'].size} samples of {axes} axis from {args.stage}")
    return 0
