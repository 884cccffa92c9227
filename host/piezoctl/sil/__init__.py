"""Software in the loop: the host's view of the SIL build.

:mod:`piezoctl.sil.stage` runs the C stage model (``firmware/targets/sil/stage``)
through ctypes, so that ``piezoctl simulate`` and the SIL firmware compute the
same samples from one parameter file.
"""

from .stage import (
    StageLibraryError,
    StageParamsError,
    default_stage_path,
    find_library,
    simulate_stage,
    stage_info,
)

__all__ = [
    "StageLibraryError",
    "StageParamsError",
    "default_stage_path",
    "find_library",
    "simulate_stage",
    "stage_info",
]
