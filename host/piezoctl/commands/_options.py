"""Options and output conventions shared by every command.

Every command that talks to a controller takes ``--port`` through
:func:`add_port` (one description of PORT); every command takes ``--json``
and ``--quiet`` through :func:`add_output` and prints its result through
:func:`emit`. Progress for anything that may take over 2 s goes to stderr
through :func:`progress`, never to stdout, so ``--json`` output stays one
JSON document.

This module is private to :mod:`piezoctl.commands` (the leading underscore
keeps :func:`piezoctl.cli.build_parser` from registering it as a command).
It imports nothing heavy: ``piezoctl --help`` must stay fast.
"""

from __future__ import annotations

import json
import sys
import time

__all__ = ["PORT_HELP", "add_port", "add_output", "emit", "progress", "Progress"]

PORT_HELP = ("controller port: tcp:HOST:PORT (Modbus TCP), rtu:DEVICE[:BAUD[:PARITY]] "
             "(Modbus RTU, default 115200 8E1) or usb[:VID:PID] (USB bulk)")


def add_port(p, *, required: bool = True, help: str | None = None) -> None:
    """Add ``--port PORT`` with the one description of PORT."""
    p.add_argument("--port", required=required, metavar="PORT",
                   help=(help + "; " if help else "") + PORT_HELP)


def add_output(p, *, json_help: str = "print the result as one JSON object on stdout") -> None:
    """Add ``--json`` and ``--quiet``."""
    p.add_argument("--json", action="store_true", help=json_help)
    p.add_argument("--quiet", action="store_true",
                   help="print nothing but the result and errors (no progress on stderr)")


def emit(args, result: dict, lines: list[str] | str | None = None) -> None:
    """Print a command's result: ``result`` as JSON with ``--json``, else ``lines``.

    ``--quiet`` without ``--json`` still prints ``lines``: they are the result.
    """
    if getattr(args, "json", False):
        print(json.dumps(result, sort_keys=True, default=_jsonable))
        return
    if lines is None:
        return
    if isinstance(lines, str):
        lines = [lines]
    for line in lines:
        print(line)


def _jsonable(o):
    try:  # numpy scalars and arrays without importing numpy here
        return o.tolist()
    except AttributeError:
        return str(o)


def progress(args, message: str) -> None:
    """One progress line on stderr, unless ``--quiet`` or ``--json``."""
    if getattr(args, "quiet", False) or getattr(args, "json", False):
        return
    print(f"piezoctl {getattr(args, 'command', '')}: {message}".replace(":  ", ": "),
          file=sys.stderr, flush=True)


class Progress:
    """Progress on stderr for a long step: ``with Progress(args, "identify"): ...``.

    Prints ``STEP ...`` when the step starts and ``STEP done (N.N s)`` when it
    ends, so no step runs silently however long it takes.
    """

    def __init__(self, args, step: str):
        self.args, self.step = args, step

    def __enter__(self):
        self.t0 = time.monotonic()
        progress(self.args, f"{self.step} ...")
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            progress(self.args, f"{self.step} done ({time.monotonic() - self.t0:.1f} s)")
        return False
