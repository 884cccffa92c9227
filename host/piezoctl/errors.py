"""Exceptions the CLI reports as one line (exit status 2) instead of a traceback."""

__all__ = ["CliError"]


class CliError(Exception):
    """An error the user caused (bad file, bad option, refused table)."""
