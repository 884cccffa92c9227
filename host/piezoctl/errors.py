"""Exceptions the CLI reports as one line instead of a traceback, and its exit codes.

Exit codes of ``piezoctl`` (``docs/recordings.md``, ``docs/model-file.md``):

======  ===========================================================================
0       success
2       the user's input was refused (:class:`CliError`: a bad file, option, table
        or target); one line ``piezoctl COMMAND: error: ...`` on stderr
3       an unexpected internal error (a bug); one line naming the exception and
        where it was raised, and a hint (``PIEZOCTL_DEBUG=1`` shows the traceback)
130     interrupted (Ctrl-C)
======  ===========================================================================
"""

__all__ = ["CliError", "EXIT_OK", "EXIT_REFUSED", "EXIT_INTERNAL", "EXIT_INTERRUPTED"]

EXIT_OK = 0
EXIT_REFUSED = 2
EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """An error the user caused (bad file, bad option, refused table)."""
