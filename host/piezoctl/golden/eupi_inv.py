"""Bit-exact golden model of ``firmware/core/eupi_inv.c`` (EUPI inverse compensator).

Per sample::

    v   = rshift_rnd((yr << 24) - g2_q39, 24)
    u   = sat_q15(rshift_rnd(a0' v + sum b'_i F'_i[v], 24))
    g2  = sum d_ij F_ij[u] + P_q39(u) - k_ex u        (Q39, kept for the next sample)

:func:`quantize_eupi_inv` is the host's acceptance check of a table: it
refuses a model whose small-gain margin is not positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q24, QOverflowError
from ..models.eupi import (EUPIParams, apply_kex, choose_kex, cpi_inverse_params,
                           eupi_inverse, small_gain_margin)
from .eupi import poly_q39, quantize_poly, reference_params, signal_cases
from .export import CHeader
from .play import WIDE_MAX, PlayBankQ, PlayBankSim, quantize_bank, realistic_drive

__all__ = ["G2_MAX_Q24", "EUPIInvQ", "quantize_eupi_inv", "eupi_inv_run",
           "reference_inverse_params", "c_header", "error_report"]

G2_MAX_Q24 = 16 << 24           # PIEZO_EUPI_INV_G2_MAX_Q24
REF_MARGIN = 0.05               # small-gain margin required of the reference table


@dataclass(frozen=True)
class EUPIInvQ:
    """Quantized inverse compensator (``struct piezo_eupi_inv_coef``)."""

    a0_inv_q24: int
    cpi_inv: PlayBankQ
    upi: PlayBankQ
    p_q24: np.ndarray
    p0_q24: int
    kex_q24: int


def quantize_eupi_inv(params: EUPIParams, u_min: float = -1.0, u_max: float = 1.0,
                      margin: float = 0.0) -> EUPIInvQ:
    """Build and quantize the inverse compensator table of ``params``.

    The CPI part ``G1 = G_CPI + k_ex u`` is inverted with
    :func:`piezoctl.models.eupi.cpi_inverse_params`; the UPI part and the
    polynomial are quantized as in the model.

    Parameters
    ----------
    params : EUPIParams
        Model with its ``k_ex`` (:func:`piezoctl.models.eupi.choose_kex`).
    u_min, u_max : float
        Drive range over which the small-gain condition must hold [FS].
    margin : float
        The table is refused unless the small-gain margin exceeds this.

    Raises
    ------
    ValueError
        The small-gain condition fails (the compensator would not be a
        contraction), or a count/slope check of the kernel fails.
    QOverflowError
        A coefficient does not fit its format, or the bound on ``|G2|`` of
        ``eupi_inv.h`` (16 FS) is exceeded.
    """
    m = small_gain_margin(params, u_min, u_max)
    if not m > margin:
        raise ValueError(f"table refused: small-gain margin {m:g} <= {margin:g} "
                         f"(a0 + k_ex must exceed max |d(G_UPI + P - k_ex u)/du|)")
    a0i, ri, bi = cpi_inverse_params(params.a0 + params.k_ex, params.r_cpi, params.b)
    a0i_q = fixed.to_q(a0i, Q24)
    if a0i_q <= 0:
        raise ValueError("a0' quantizes to 0")
    cpi_inv = quantize_bank(ri, None, bi, r_max_q15=WIDE_MAX)
    if params.n_upi:
        upi = quantize_bank(params.r_upi, params.a_upi, params.d, r_max_q15=Q15.max)
    else:
        upi = PlayBankQ(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
    p_q, p0_q = quantize_poly(params.p, params.p0)
    kex_q = fixed.to_q(params.k_ex, Q24)
    g2_max = 2 * int(np.sum(upi.w_q24)) + int(np.sum(np.abs(p_q))) + abs(p0_q) + abs(kex_q)
    if g2_max > G2_MAX_Q24:
        raise QOverflowError(f"bound on |G2| {g2_max / 2**24:g} exceeds 16 FS")
    return EUPIInvQ(a0i_q, cpi_inv, upi, p_q, p0_q, kex_q)


def eupi_inv_run(q: EUPIInvQ, yr_q15, state=None, return_state: bool = False):
    """Run ``piezo_eupi_inv_process`` on every sample of ``yr_q15``.

    Parameters
    ----------
    q : EUPIInvQ
    yr_q15 : array_like of int, shape (T,)
        Desired displacement, q15.
    state : (f_cpi_inv, f_upi, g2_q39) or None
        State to start from (None: as after reset, ``g2 = P(0)``).
    return_state : bool
        Also return the state after the last sample.

    Returns
    -------
    u : ndarray of int64, shape (T,)
        Drive, q15 (clamped).
    state : (f_cpi_inv, f_upi, g2_q39), only if ``return_state``.
    """
    yr = np.asarray(yr_q15, dtype=np.int64)
    if np.any(yr < Q15.min) or np.any(yr > Q15.max):
        raise ValueError("input must be q15")
    cpi = PlayBankSim(q.cpi_inv, None if state is None else state[0])
    upi = PlayBankSim(q.upi, None if state is None else state[1])
    g2 = poly_q39(q.p_q24, q.p0_q24, 0) if state is None else int(state[2])
    a0i, kex = int(q.a0_inv_q24), int(q.kex_q24)
    out = np.empty(yr.size, dtype=np.int64)
    for k in range(yr.size):
        v = fixed.rshift_rnd((int(yr[k]) << 24) - g2, 24)
        u = fixed.sat_q15(fixed.rshift_rnd(a0i * v + cpi.step(v), 24))
        out[k] = u
        g2 = upi.step(u) + poly_q39(q.p_q24, q.p0_q24, u) - kex * u
    if return_state:
        return out, (cpi.f.copy(), upi.f.copy(), g2)
    return out


def reference_inverse_params() -> EUPIParams:
    """The reference model with ``k_ex = choose_kex(margin=0.2)``.

    The model's own margin (0.15 at ``k_ex = 0``) already passes; asking for
    0.2 makes ``k_ex > 0`` so that the vectors exercise it.
    """
    p = reference_params()
    return apply_kex(p, choose_kex(p, margin=0.2))


def _yr_realistic(n: int) -> np.ndarray:
    """A desired displacement inside the reference model's range [FS]."""
    return 0.6 * realistic_drive(n)


def c_header() -> str:
    """Golden vectors of the inverse compensator on the issue's cases; the
    edges case asks for more than the model can give, so the drive clamps."""
    params = reference_inverse_params()
    q = quantize_eupi_inv(params, margin=REF_MARGIN)
    h = CHeader("eupi_inv")
    h.define("GOLDEN_EUPI_INV_A0I_Q24", q.a0_inv_q24)
    h.define("GOLDEN_EUPI_INV_KEX_Q24", q.kex_q24)
    h.define("GOLDEN_EUPI_INV_P0_Q24", q.p0_q24)
    h.define("GOLDEN_EUPI_INV_NCPI", q.cpi_inv.r_q15.size)
    h.define("GOLDEN_EUPI_INV_NUR", q.upi.r_q15.size)
    h.define("GOLDEN_EUPI_INV_NUA", q.upi.a_q24.size)
    h.define("GOLDEN_EUPI_INV_NP", q.p_q24.size)
    h.array("golden_eupi_inv_r_cpi_q15", "int32_t", q.cpi_inv.r_q15)
    h.array("golden_eupi_inv_b_q24", "int32_t", q.cpi_inv.w_q24)
    h.array("golden_eupi_inv_r_upi_q15", "int32_t", q.upi.r_q15)
    h.array("golden_eupi_inv_a_upi_q24", "int32_t", q.upi.a_q24)
    h.array("golden_eupi_inv_d_q24", "int32_t", q.upi.w_q24)
    h.array("golden_eupi_inv_p_q24", "int32_t", q.p_q24)
    rng = np.random.default_rng(13)
    cases = dict(signal_cases(rng))
    cases["realistic"] = np.floor(_yr_realistic(2000) * 32768.0 + 0.5)
    for name, yr in cases.items():
        yr = np.asarray(yr, dtype=np.int64)
        u = eupi_inv_run(q, yr)
        h.comment(f"reference inverse, {name} input")
        h.define(f"GOLDEN_EUPI_INV_{name.upper()}_N", yr.size)
        h.array(f"golden_eupi_inv_{name}_yr", "int16_t", yr)
        h.array(f"golden_eupi_inv_{name}_u", "int16_t", u)
        if name == "edges":
            assert u.max() == Q15.max and u.min() == Q15.min, "edges must clamp the drive"
    yr = np.asarray(cases["realistic"], dtype=np.int64)
    half = yr.size // 2
    u1, st = eupi_inv_run(q, yr[:half], return_state=True)
    u2 = eupi_inv_run(q, yr[half:], state=st)
    h.comment("realistic input in two blocks, golden state carried over")
    h.define("GOLDEN_EUPI_INV_SPLIT_HALF", half)
    h.array("golden_eupi_inv_split_u", "int16_t", np.concatenate([u1, u2]))
    return str(h)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, u_float, u_fixed_q15) of the reference inverse on a realistic
    desired displacement: the float compensator
    (:func:`piezoctl.models.eupi.eupi_inverse`, clamped to [-1, 1)) against
    the fixed-point one, both fed the same q15 ``yr``."""
    params = reference_inverse_params()
    yr_q = np.floor(_yr_realistic(20000) * 32768.0 + 0.5).astype(np.int64)
    u_fixed = eupi_inv_run(quantize_eupi_inv(params, margin=REF_MARGIN), yr_q)
    u_float = eupi_inverse(yr_q / 32768.0, params, u_range=(-1.0, Q15.max / 32768.0))
    return [("reference EUPI inverse, realistic yr", u_float, u_fixed)]
