"""Command-line entry point: ``piezoctl <command> ...`` (``tools/piezoctl``).

Commands are the modules of :mod:`piezoctl.commands`; each registers itself
with ``add_parser(subparsers)``. A user error (bad file, bad option) raises
:class:`CliError` and is printed as one line with exit status 2. Anything
else that escapes a command is a bug: the last-resort guard in :func:`main`
prints it as one line with where it was raised and exits with status 3
(``PIEZOCTL_DEBUG=1`` re-raises it with the traceback). Exit codes:
:mod:`piezoctl.errors`.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys
import traceback

from . import __version__, commands
from .errors import EXIT_INTERNAL, EXIT_INTERRUPTED, CliError, exit_code

__all__ = ["main", "build_parser", "CliError"]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="piezoctl",
        description="Piezo nanopositioning controller: identify, tabulate, flash, diagnose.")
    ap.add_argument("--version", action="version", version=f"piezoctl {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):  # shared helpers, not commands
            continue
        importlib.import_module(f"{commands.__name__}.{info.name}").add_parser(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if not getattr(args, "func", None):
        ap.print_help()
        return 0
    if not os.environ.get("PIEZOCTL_DEBUG"):
        # pymodbus logs a failed connect on stderr; the command reports it as its one error line
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    try:
        return int(args.func(args) or 0)
    except CliError as exc:
        print(f"piezoctl {args.command}: error: {exc}", file=sys.stderr)
        return exit_code(exc)
    except KeyboardInterrupt:
        print(f"piezoctl {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except MemoryError:
        print(f"piezoctl {args.command}: error: out of memory (hint: a shorter input or a smaller model)",
              file=sys.stderr)
        return EXIT_INTERNAL
    except Exception as exc:  # last resort: the causes are fixed where they arise
        if os.environ.get("PIEZOCTL_DEBUG"):
            raise
        print(f"piezoctl {args.command}: internal error: {_one_line(exc)} "
              f"(hint: this is a bug; rerun with PIEZOCTL_DEBUG=1 for the traceback and report it)",
              file=sys.stderr)
        return EXIT_INTERNAL


def _one_line(exc: BaseException) -> str:
    """``Type: message at file:line`` of the innermost frame in piezoctl (or the last one)."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if f"{os.sep}piezoctl{os.sep}" in f.filename] or frames
    where = f" at {os.path.relpath(ours[-1].filename, os.path.dirname(os.path.dirname(__file__)))}:{ours[-1].lineno}" \
        if ours else ""
    msg = " ".join(str(exc).split())[:300]
    return f"{type(exc).__name__}: {msg}{where}"


if __name__ == "__main__":
    sys.exit(main())
