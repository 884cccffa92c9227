"""Command-line entry point: ``piezoctl <command> ...`` (``tools/piezoctl``).

Commands are the modules of :mod:`piezoctl.commands`; each registers its
command(s) with ``add_parser(subparsers)``. :data:`COMMANDS` names the module
and the one-line summary of every command, so that ``piezoctl --help`` lists
them without importing any, and ``piezoctl COMMAND ...`` imports only the
module of COMMAND (the start-up stays under 0.5 s: ``tools/bench-cli``). A
command module missing from the table still works, imported on every start.

A user error (bad file, bad option) raises :class:`CliError` and is printed
as one line ``piezoctl COMMAND: error: ...``. Anything else that escapes a
command is a bug: the last-resort guard in :func:`main` prints it as one line
with where it was raised and exits with status 3 (``PIEZOCTL_DEBUG=1``
re-raises it with the traceback and lets library logs and warnings through).

Exit codes (:mod:`piezoctl.errors`): 0 ok, 1 a check failed, 2 usage or
input refused, 3 internal error, 4 the controller refused, 5 no connection,
130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import pkgutil
import sys
import traceback
import warnings

from . import __version__, commands
from .errors import (EXIT_CONNECTION, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_OUTPUT_CLOSED, EXIT_REFUSED, CliError,
                     exit_code)

__all__ = ["main", "build_parser", "CliError", "CommandParser", "COMMANDS"]

# command -> (module in piezoctl.commands, the one-line summary of ``piezoctl --help``).
# The summary must equal the ``help=`` the module passes (tests/host/test_cli.py checks).
COMMANDS: dict[str, tuple[str, str]] = {
    "calibrate": ("calibrate", "calibrate a stage end to end (identify, flash, accept, report)"),
    "diagnose": ("diagnose", "locate a model/data mismatch, name the missing physics, model it"),
    "fit-tf": ("fit_tf", "fit a transfer function (WCLS / PSO-WCLS) to a frequency response (FRF.csv, or "
                         "estimated from a recording)"),
    "flash": ("flash", "upload a table image, verify, commit, confirm"),
    "frf": ("frf", "estimate the frequency response of a recording (H1, coherence) into FRF.csv"),
    "golden-error": ("golden_error", "float-versus-fixed error table of the core kernels"),
    "identify": ("identify", "fit a hysteresis model to recordings and write MODEL.json"),
    "move": ("move", "move the stage to a position [um] (--wait: until settled)"),
    "params": ("params", "controller parameters: get, set, save to flash, load, defaults"),
    "position": ("position", "the stage's position (once, or --follow until Ctrl-C)"),
    "record": ("record", "record controller signals for a duration into a recording CSV"),
    "servo": ("servo", "closed loop on (at the present position) or off (hold the drive)"),
    "simulate": ("simulate", "run a model on a recording's drive and write t,y"),
    "stage": ("stage", "the simulated stage (C stage model of the SIL build)"),
    "status": ("status", "identity and status of a controller"),
    "tables": ("tables", "coefficient tables: build from a model, list a controller's, roll back"),
    "wave": ("wave", "load and start the wave generator (optionally recording the run), or stop it"),
}

# Libraries whose exceptions mean the link to the controller failed (exit 5)
# when one escapes the transport layer unwrapped.
_LINK_LIBRARIES = ("serial", "usb", "pymodbus")


class CommandParser(argparse.ArgumentParser):
    """The parser of ``piezoctl`` and of each command.

    - A usage error is one line on stderr, ``PROG: error: MESSAGE (see PROG
      --help)``, and exit status 2 (argparse prints the whole usage).
    - :meth:`before_parse` registers work (e.g. options that need heavy
      imports, or depend on other options) to run each time this parser
      parses or prints its help, not when the top-level parser is built.
    - ``explain_unknown(extras) -> str | None`` (an attribute a command may
      set) turns unrecognized arguments into a clearer message.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._before: list = []
        self.explain_unknown = None

    def before_parse(self, fn) -> None:
        """Call ``fn(self, args)`` before each parse (``args``: what it parses)
        and before formatting the help (``args`` None)."""
        self._before.append(fn)

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        for fn in self._before:
            fn(self, args)
        ns, extras = super().parse_known_args(args, namespace)
        if extras and self.explain_unknown is not None:
            msg = self.explain_unknown(extras)
            if msg:
                self.error(msg)
        return ns, extras

    def format_help(self) -> str:
        for fn in self._before:
            fn(self, None)
        return super().format_help()

    def error(self, message: str):
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        sys.exit(EXIT_REFUSED)


def _command_modules() -> list[str]:
    """Names of the command modules (not the ``_``-prefixed helpers), without importing them."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_"))


def build_parser(argv: list[str] | None = None) -> CommandParser:
    """The ``piezoctl`` parser.

    With ``argv`` (what :func:`main` does), only the module of the command
    named in ``argv`` (and any module missing from :data:`COMMANDS`) is
    imported; the other commands are registered by name and summary alone.
    Without, every command module is imported (a parser for any command line).
    """
    ap = CommandParser(
        prog="piezoctl",
        description="Piezo nanopositioning controller: identify, tabulate, flash, diagnose.",
        epilog="exit status: 0 ok, 1 a check failed, 2 usage or input refused, 3 internal error, "
               "4 the controller refused, 5 no connection, 130 interrupted")
    ap.add_argument("--version", action="version", version=f"piezoctl {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", parser_class=CommandParser)
    chosen = next((a for a in (argv or []) if not a.startswith("-")), None)
    listed = {mod for mod, _ in COMMANDS.values()}
    load = {m for m in _command_modules() if argv is None or m not in listed}
    if chosen in COMMANDS:
        load.add(COMMANDS[chosen][0])
    for name in sorted(load):
        importlib.import_module(f"{commands.__name__}.{name}").add_parser(sub)
    for name, (mod, summary) in COMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=summary, add_help=False)
    # argparse lists commands in registration order; list them alphabetically
    sub._choices_actions.sort(key=lambda a: a.dest)
    return ap


@contextlib.contextmanager
def _quiet_libraries():
    """Keep library log lines and warnings out of the output while a command runs
    (a command reports in its own words); the logging and warnings state is
    restored afterwards.

    A NullHandler on the root logger stops logging's last-resort handler from
    printing the WARNING lines of pymodbus, matplotlib and the like; warnings
    (numpy's RuntimeWarning, ...) are ignored.
    """
    root = logging.getLogger()
    null = logging.NullHandler()
    root.addHandler(null)
    pymodbus = logging.getLogger("pymodbus")
    level = pymodbus.level
    pymodbus.setLevel(logging.CRITICAL + 1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        pymodbus.setLevel(level)
        root.removeHandler(null)


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    ap = build_parser(argv)
    args = ap.parse_args(argv)
    if not getattr(args, "func", None):
        ap.print_help()
        return 0
    os.environ.setdefault("MPLBACKEND", "Agg")  # no display: plots go to files
    quiet = contextlib.nullcontext() if os.environ.get("PIEZOCTL_DEBUG") else _quiet_libraries()
    try:
        with quiet:
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
        if isinstance(exc, BrokenPipeError) and _stdout_closed():
            # `piezoctl ... | head`: the reader left; not the controller's link (also a BrokenPipeError)
            with contextlib.suppress(OSError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return EXIT_OUTPUT_CLOSED
        if os.environ.get("PIEZOCTL_DEBUG"):
            raise
        if isinstance(exc, ConnectionError) or type(exc).__module__.split(".")[0] in _LINK_LIBRARIES:
            # the link failed below the transport layer's own checks
            print(f"piezoctl {args.command}: error: connection to the controller failed: "
                  f"{' '.join(str(exc).split())[:300] or type(exc).__name__}", file=sys.stderr)
            return EXIT_CONNECTION
        print(f"piezoctl {args.command}: internal error: {_one_line(exc)} "
              f"(hint: this is a bug; rerun with PIEZOCTL_DEBUG=1 for the traceback and report it)",
              file=sys.stderr)
        return EXIT_INTERNAL


def _stdout_closed() -> bool:
    """True when stdout is a pipe whose reader went away (poll reports an error on it)."""
    import select
    try:
        p = select.poll()
        p.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in p.poll(0))
    except (OSError, ValueError, AttributeError):
        return False


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
