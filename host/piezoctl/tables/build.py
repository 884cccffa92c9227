"""Coefficient tables from quantized kernel coefficients.

Each ``*_sections`` function turns the golden model's quantized coefficients
(exactly what the C kernels run) into the payload sections of one table kind
(``common/interface.toml`` ``[table.sections]``); :func:`build_image` of
:mod:`piezoctl.tables.image` assembles the image. :func:`firmware_small_gain`
is the integer twin of the firmware's commit check, so the host refuses a
table before the controller would.
"""

from __future__ import annotations

import numpy as np

from .. import fixed, interface
from ..fixed import Q24
from ..golden.dcc import DCCQ
from ..golden.eupi_inv import EUPIInvQ
from ..golden.kp import KPGridQ
from ..golden.rkp import RKPQ
from .image import Section, TableImageError

__all__ = ["ctl_section", "kp_dcc_sections", "rkp_sections", "eupi_inverse_sections",
           "firmware_small_gain", "cross_coupling_sections"]

_I16 = interface.SECTION_TYPES["int16"]
_I32 = interface.SECTION_TYPES["int32"]


def _sec(name: str, values) -> Section:
    sid, typ, _kinds = interface.TABLE_SECTIONS[name]
    return Section(sid, np.asarray(values, dtype=np.int64).ravel(), _I16 if typ == "int16" else _I32)


def ctl_section(open_loop_gain: float, open_loop_offset: float = 0.0,
                y_to_u_gain: float = 1.0, y_offset: float = 0.0) -> Section:
    """Controller scalars: the straight lines from the reference r (position, FS).

    Parameters
    ----------
    open_loop_gain, open_loop_offset : float
        Uncompensated drive ``u = g r + o`` [FS/FS, FS].
    y_to_u_gain, y_offset : float
        The DCC law's input ``yd = g' r + o'`` (the model's output units) [FS/FS, FS].
    """
    g = [fixed.to_q(open_loop_gain, Q24), fixed.to_q(y_to_u_gain, Q24)]
    o = [fixed.to_q(open_loop_offset, fixed.Q15W), fixed.to_q(y_offset, fixed.Q15W)]
    if min(g) <= 0:
        raise TableImageError("out_of_range", "controller gains must be positive")
    if max(abs(v) for v in o) > 65536:
        raise TableImageError("out_of_range", "controller offsets must be within +-2 FS")
    return _sec("ctl_scalars", [g[0], o[0], g[1], o[1]])


def _grid_sections(g: KPGridQ) -> list[Section]:
    return [_sec("kp_grid", [g.nmin, g.rmax, g.slope, g.xsat]),
            _sec("kp_n1_q15", g.n1), _sec("kp_n2_q15", g.n2)]


def kp_dcc_sections(d: DCCQ) -> list[Section]:
    """KP operators and the DCC law (kind ``kp_dcc``)."""
    return _grid_sections(d.grid) + [_sec("dcc_c_q24", d.c), _sec("dcc_g_q24", [d.g])]


def rkp_sections(r: RKPQ, g_q24: int) -> list[Section]:
    """Rate-dependent DCC (kind ``rkp``): ``r.theta`` must already hold g * Theta."""
    return _grid_sections(r.grid) + [
        _sec("rkp_theta_q24", r.theta), _sec("rkp_center_q24", r.center),
        _sec("rkp_inv_width_q16", r.inv_width), _sec("rkp_alpha_q16", [r.alpha]),
        _sec("dcc_g_q24", [g_q24])]


def firmware_small_gain(q: EUPIInvQ, a0_q24: int) -> tuple[bool, float]:
    """The firmware's integer small-gain check (``coefset.c``), and its margin [FS].

    Returns
    -------
    ok : bool
        True when ``a0 + k_ex > max(S + Pb - k_ex, k_ex + Pb)`` in q48.
    margin : float
        ``a0 + k_ex`` minus the bound, in full-scale units.
    """
    one = 1 << 24
    big_a0 = int(a0_q24) + int(q.kex_q24)
    s = 0
    na = q.upi.a_q24.size
    for i in range(q.upi.r_q15.size):
        for j in range(na):
            s += int(q.upi.w_q24[i * na + j]) * max(one, int(q.upi.a_q24[j]))
    pb = sum((m + 2) * abs(int(p)) * one for m, p in enumerate(q.p_q24))
    kex = int(q.kex_q24) * one
    bound = max(s + pb - kex, kex + pb)
    lhs = big_a0 * one
    ok = int(a0_q24) > 0 and big_a0 > 0 and lhs > bound
    return ok, (lhs - bound) / float(1 << 48)


def eupi_inverse_sections(q: EUPIInvQ, a0: float) -> list[Section]:
    """The EUPI inverse compensator (kind ``eupi_inverse``).

    Raises
    ------
    TableImageError
        ``unstable_inverse`` when the firmware's integer check would refuse it.
    """
    a0_q24 = fixed.to_q(a0, Q24)
    ok, margin = firmware_small_gain(q, a0_q24)
    if not ok:
        raise TableImageError("unstable_inverse",
                              f"small-gain bound not met in the firmware's integer check "
                              f"(margin {margin:.4g} FS)")
    return [
        _sec("eupi_inv_scalars", [q.a0_inv_q24, q.kex_q24, q.p0_q24, a0_q24]),
        _sec("eupi_cpi_inv_r_q15", q.cpi_inv.r_q15), _sec("eupi_cpi_inv_w_q24", q.cpi_inv.w_q24),
        _sec("eupi_upi_r_q15", q.upi.r_q15), _sec("eupi_upi_a_q24", q.upi.a_q24),
        _sec("eupi_upi_w_q24", q.upi.w_q24), _sec("eupi_poly_q24", q.p_q24),
    ]


def cross_coupling_sections(k, x_source: int = 0) -> list[Section]:
    """Sections of a ``cross_coupling`` table from the xcouple kernel's quantized
    coefficients (:class:`piezoctl.golden.xcouple.XCoef` of integers, checked
    as the firmware checks them). ``x_source``: 0 = the position input is this
    axis' position, 1 = the other axis'."""
    from ..golden import xcouple as gxc
    if x_source not in (0, 1):
        raise TableImageError("out_of_range", "x_source must be 0 or 1")
    try:
        gxc.check(k)
    except (ValueError, fixed.QOverflowError) as exc:
        raise TableImageError("out_of_range", str(exc)) from None
    scal = [k.m, k.n_ch, k.n_pow, k.n_deg, k.u_center, k.u_gain, k.x_center, k.x_gain, x_source]
    return [_sec("xc_scalars", scal), _sec("xc_a_q24", k.a), _sec("xc_b_q24", k.b), _sec("xc_e_q24", k.e),
            _sec("xc_eta_q24", k.eta), _sec("xc_xi_q24", k.xi)]
