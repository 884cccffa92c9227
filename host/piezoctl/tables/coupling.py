"""Cross-coupling table (kind ``cross_coupling``) from an identified coupling map.

The map is a host ``hammerstein`` model (:mod:`piezoctl.ident.hammerstein`)
fitted with the firmware kernel's restrictions (no trigonometric input
functions, powers 0..7, degree <= 3, m <= 4, at most 2 channels): the other
axis' drive [V] in, the coupled displacement of this axis [um] out, at a
position [um]. :func:`coupling_table` converts it to the kernel's form on the
controller's q15 scales, with the output in this axis' drive units (the
coupling divided by this axis' static gain), quantizes it with the golden
quantizer (the firmware's checks) and builds the image.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..golden import xcouple as gxc
from .build import cross_coupling_sections
from .image import build_image

__all__ = ["CouplingTable", "coupling_table", "KERNEL_SETTINGS"]

# hammerstein identification settings for the kernel: the paper's Laguerre pole
# (q T = 0.2 per sample) with m = 4 filters (at 10 kHz the coupling's phase
# from the 140 Hz mode needs more than the paper's 2), cubic drive, quadratic
# position, one channel (on the two-axis SIL stage 1 channel predicts the 1-50 Hz
# coupling better than 2 after refinement: docs/cross-coupling.md)
KERNEL_SETTINGS = {"m": 4, "q": 0.1, "T": 2.0, "degree": 2, "powers": [0, 1, 2, 3], "harmonics": 0,
                   "channels": 1, "refine": 20}


@dataclass(frozen=True)
class CouplingTable:
    image: bytes
    coef_float: gxc.XCoef
    coef_q: gxc.XCoef
    x_source: int


def coupling_table(params: dict, drive_scale, position_scale, drive_per_um: float, *, x_source: int = 0,
                   table_version: int = 1, fit_nrmse: float = 0.0, build_time: int = 0,
                   data_sha256: bytes = b"", axis: int = 0, stage=None) -> CouplingTable:
    """Image of the coupling table for one axis.

    Parameters
    ----------
    params : dict
        Hammerstein parameters (u: the other axis' drive [V], x: the position
        the table's ``x_source`` names [um], y: coupling into this axis [um]).
    drive_scale : Scale
        The other axis' drive scale (q15 <-> V).
    position_scale : Scale
        The position input's scale (q15 <-> um).
    drive_per_um : float
        This axis' drive [FS] per um of displacement: 1 / static gain.
    axis : int
        The controller axis the table goes to.
    stage : Scale, optional
        That axis' own scale (drive and position ranges), stamped into the
        header; a controller of another stage refuses the table. None: no
        stage (only a controller that does not know its own accepts it).
    """
    kf = gxc.from_hammerstein(params, drive_scale, position_scale, drive_per_um)
    kq = gxc.quantize(kf)
    st = {} if stage is None else dict(drive_range_v=(stage.drive_min_v, stage.drive_max_v),
                                       position_range_um=(stage.position_min_um, stage.position_max_um))
    img = build_image("cross_coupling", cross_coupling_sections(kq, x_source), table_version=table_version,
                      fit_nrmse=fit_nrmse, build_time=build_time, data_sha256=data_sha256, axis=axis, **st)
    return CouplingTable(img, kf, kq, x_source)
