"""Exceptions the CLI reports as one line instead of a traceback, and its exit codes.

Exit codes of ``piezoctl`` (``docs/recordings.md``, ``docs/model-file.md``):

======  ===========================================================================
0       success
1       a check failed: the command ran, but what it measured did not pass
        (:class:`CheckFailed`: e.g. a calibration's acceptance test)
2       usage or input refused (:class:`CliError`: a bad option, file, table or
        target); one line ``piezoctl COMMAND: error: ...`` on stderr
3       an unexpected internal error (a bug); one line naming the exception and
        where it was raised, and a hint (``PIEZOCTL_DEBUG=1`` shows the traceback)
4       the controller refused (:class:`ControllerRefused`: a Modbus exception, a
        table the controller would not commit, a locked controller)
5       no connection (:class:`ConnectionFailed`: the port cannot be opened, or the
        controller stopped answering)
130     interrupted (Ctrl-C)
======  ===========================================================================
"""

__all__ = ["CliError", "CheckFailed", "ControllerRefused", "ConnectionFailed", "exit_code",
           "EXIT_OK", "EXIT_CHECK_FAILED", "EXIT_REFUSED", "EXIT_INTERNAL", "EXIT_CONTROLLER",
           "EXIT_CONNECTION", "EXIT_INTERRUPTED", "EXIT_OUTPUT_CLOSED"]

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_REFUSED = 2
EXIT_INTERNAL = 3
EXIT_CONTROLLER = 4
EXIT_CONNECTION = 5
EXIT_INTERRUPTED = 130
EXIT_OUTPUT_CLOSED = 141   # 128 + SIGPIPE, as a shell reports it: the reader of stdout went away (| head)


class CliError(Exception):
    """An error the user caused (bad file, bad option, refused table): exit 2."""


class CheckFailed(CliError):
    """The command ran but a check it makes did not pass: exit 1."""


class ControllerRefused(CliError):
    """The controller refused a request (exception response, refused commit): exit 4."""


class ConnectionFailed(CliError):
    """The controller cannot be reached or stopped answering: exit 5."""


def exit_code(exc: CliError) -> int:
    """The exit status for a :class:`CliError` (its class decides)."""
    if isinstance(exc, CheckFailed):
        return EXIT_CHECK_FAILED
    if isinstance(exc, ControllerRefused):
        return EXIT_CONTROLLER
    if isinstance(exc, ConnectionFailed):
        return EXIT_CONNECTION
    return EXIT_REFUSED
