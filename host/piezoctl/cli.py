"""Command-line entry point: ``piezoctl <command> ...`` (``tools/piezoctl``).

Each command lives in its own module and registers itself in :data:`COMMANDS`
with ``add_parser(subparsers)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__

# command name -> module implementing add_parser(subparsers) and run(args)
COMMANDS = {
    "golden-error": "piezoctl.golden.error_table",
}


class CliError(Exception):
    """An error the user caused (bad file, bad option): printed as one line, exit 2."""


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="piezoctl",
        description="Piezo nanopositioning controller: identify, tabulate, flash, diagnose.")
    ap.add_argument("--version", action="version", version=f"piezoctl {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    for name, modname in COMMANDS.items():
        mod = importlib.import_module(modname)
        mod.add_parser(sub)
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
