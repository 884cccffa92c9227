"""All or nothing: a command that writes several files removes the ones it wrote when a later one fails.

Private to :mod:`piezoctl.commands` (not a command). Usage::

    with Outputs() as out:
        out.write(args.out, lambda p: write_csv(p, ...))
        if args.plot:
            out.write(args.plot, lambda p: plots.bode(p, ...))

If anything raises inside the block, every file written in it is removed
(a file that existed before is not restored: the command refused, and says so).
"""

from __future__ import annotations

import os

from ..errors import CliError

__all__ = ["Outputs", "check_output_paths"]


def check_output_paths(*paths) -> None:
    """Refuse, before any work, an output whose folder does not exist or that is a folder."""
    for p in paths:
        if p is None:
            continue
        p = os.fspath(p)
        parent = os.path.dirname(os.path.abspath(p))
        if os.path.isdir(p):
            raise CliError(f"{p}: is a folder, not a file to write")
        if not os.path.isdir(parent):
            raise CliError(f"{p}: cannot write: folder {parent} does not exist")


class Outputs:
    """Files written by one command run; removed again if the run fails."""

    def __init__(self):
        self.paths: list[str] = []

    def write(self, path, writer) -> None:
        """Call ``writer(path)`` and remember ``path``."""
        self.paths.append(os.fspath(path))
        writer(path)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            for p in self.paths:
                try:
                    os.unlink(p)
                except OSError:
                    pass
        return False
