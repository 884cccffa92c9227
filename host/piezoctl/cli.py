"""Command-line entry point: ``piezoctl <command> ...`` (``tools/piezoctl``).

Commands are the modules of :mod:`piezoctl.commands`; each registers itself
with ``add_parser(subparsers)``. A user error (bad file, bad option) raises
:class:`CliError` and is printed as one line with exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import __version__, commands
from .errors import CliError

__all__ = ["main", "build_parser", "CliError"]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="piezoctl",
        description="Piezo nanopositioning controller: identify, tabulate, flash, diagnose.")
    ap.add_argument("--version", action="version", version=f"piezoctl {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        importlib.import_module(f"{commands.__name__}.{info.name}").add_parser(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if not getattr(args, "func", None):
        ap.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"piezoctl {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
