"""``piezoctl golden-error``: float-versus-fixed error table of the core kernels."""

from __future__ import annotations

from ..golden import error_table


def add_parser(sub) -> None:
    p = sub.add_parser("golden-error", help="float-versus-fixed error table of the core kernels")
    p.add_argument("--out", help="also write the table (Markdown) to this file")
    p.set_defaults(func=run)


def run(args) -> int:
    text = error_table.markdown(error_table.rows())
    print(text, end="")
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text)
    return 0
