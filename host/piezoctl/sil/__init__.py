"""Software in the loop: the host's view of the SIL build.

:mod:`piezoctl.sil.stage` runs the C stage model (``firmware/targets/sil/stage``)
through ctypes, so that ``piezoctl simulate`` and the SIL firmware compute the
same samples from one parameter file. :mod:`piezoctl.sil.launch` starts the
virtual controller (``sil_stage``): the one launcher every tool and test uses.

The names of :mod:`piezoctl.sil.stage` are re-exported here on first use, so
importing :mod:`piezoctl.sil.launch` does not import numpy.
"""

__all__ = [
    "StageLibraryError",
    "StageParamsError",
    "default_stage_path",
    "find_library",
    "simulate_stage",
    "stage_info",
]


def __getattr__(name):
    if name in __all__:
        from . import stage
        return getattr(stage, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
