"""One module per CLI command (``piezoctl <command>``).

Each module provides ``add_parser(subparsers)``, which registers the command and
sets ``func`` to a ``run(args) -> int``. :mod:`piezoctl.cli` finds them here.
"""
