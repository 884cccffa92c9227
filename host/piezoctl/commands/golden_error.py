"""``piezoctl golden-error [--out FILE] [--json] [--quiet]``: float-versus-fixed error table of the core kernels.

Text: the Markdown table (kernel, signal, max error [LSB q15], SNR [dB]);
``--json``: ``{"rows": [{"kernel", "signal", "max_error_lsb", "snr_db"}], "out"}``.
Takes a few seconds (every kernel runs its float and fixed-point twins):
progress on stderr.
"""

from __future__ import annotations

from ._options import Progress, add_output, emit


def add_parser(sub) -> None:
    p = sub.add_parser("golden-error", help="float-versus-fixed error table of the core kernels")
    p.add_argument("--out", metavar="FILE.md", help="also write the table (Markdown) to this file")
    add_output(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..golden import error_table  # here: the start-up imports no numpy
    with Progress(args, "running the float and fixed-point kernels"):
        table = error_table.rows()
    text = error_table.markdown(table)
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text)
    emit(args, {"rows": [{"kernel": k, "signal": case, "max_error_lsb": mx,
                          "snr_db": (None if snr == float("inf") else snr)}
                         for k, case, mx, snr in table], "out": args.out},
         text.rstrip("\n").split("\n"))
    return 0
