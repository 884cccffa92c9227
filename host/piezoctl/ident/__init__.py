"""Offline identification of model parameters from recordings.

Every model kind is a module here with the same small interface, listed in
:data:`MODEL_KINDS` (``piezoctl identify --model KIND``):

- ``KIND: str`` and ``DESCRIPTION: str``
- ``add_options(parser)``: the kind's own ``identify`` options, each with a default
- ``fit(recordings, options) -> dict``: JSON-serializable parameters (physical units)
- ``simulate(params, t, u, u2=None) -> ndarray``: model output y [um] for drive u [V]
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["MODEL_KINDS", "get_kind"]

MODEL_KINDS = {
    "kp": "piezoctl.ident.kp",
    "rkp": "piezoctl.ident.rkp",
    "eupi": "piezoctl.ident.eupi",
    "preisach": "piezoctl.ident.preisach",
    "cascade": "piezoctl.ident.cascade",
    "hammerstein": "piezoctl.ident.hammerstein",
    "refined": "piezoctl.ident.refined",
}


def get_kind(name: str) -> ModuleType:
    """Import the module of model kind ``name`` (a key of :data:`MODEL_KINDS`)."""
    try:
        modname = MODEL_KINDS[name]
    except KeyError:
        raise ValueError(f"unknown model kind {name!r}; known: {', '.join(MODEL_KINDS)}") from None
    return importlib.import_module(modname)
