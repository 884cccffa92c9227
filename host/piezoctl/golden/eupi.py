"""Bit-exact golden model of ``firmware/core/eupi.c`` (EUPI hysteresis model).

``y = sat_q15(rshift_rnd(a0 u + sum b F_CPI + sum d F_UPI + P_q39(u), 24))``
with the play banks of :mod:`piezoctl.golden.play` and the polynomial by
Horner, each step rounded to Q7.24 (:func:`poly_q39`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q24, QOverflowError
from ..models.eupi import EUPIParams, eupi_model
from .export import CHeader
from .play import PlayBankQ, PlayBankSim, quantize_bank, realistic_drive

__all__ = [
    "MAX_POLY", "POLY_SUM_MAX_Q24", "EUPIQ", "reference_params", "quantize_eupi",
    "quantize_poly", "poly_q39", "eupi_run", "c_header", "error_report",
]

MAX_POLY = 8                    # PIEZO_EUPI_MAX_POLY
POLY_SUM_MAX_Q24 = 64 << 24     # PIEZO_EUPI_POLY_SUM_MAX_Q24; sum |p_m| must stay below it


@dataclass(frozen=True)
class EUPIQ:
    """Quantized EUPI coefficients (``struct piezo_eupi_coef``)."""

    a0_q24: int
    cpi: PlayBankQ
    upi: PlayBankQ
    p_q24: np.ndarray
    p0_q24: int


def reference_params() -> EUPIParams:
    """The reference benchmark model: 10 CPI, 10 x 3 UPI operators, ``u^2..u^4``.

    Initial loading maps drive -1 and 1 to about -0.61 and 0.73 (full
    scale); the small-gain margin at ``k_ex = 0`` is about 0.15.
    """
    rng = np.random.default_rng(11)
    return EUPIParams(
        a0=0.42,
        r_cpi=np.linspace(0.0, 0.9, 10),
        b=np.round(rng.uniform(0.01, 0.06, 10), 6),
        r_upi=np.linspace(0.0, 0.9, 10),
        a_upi=np.array([0.6, 1.0, 1.45]),
        d=np.round(rng.uniform(0.0, 0.008, (10, 3)), 6),
        p=np.array([0.06, 0.03, -0.02]),
        p0=0.015,
    )


def quantize_poly(p, p0) -> tuple[np.ndarray, int]:
    """Quantize polynomial coefficients to Q7.24 and check ``eupi.h``'s bounds.

    The sum bound is strict (round 18): ``sum |p_m| < 64`` keeps the Horner
    value ``|h| < 2^30``, where ``piezo_eupi_poly_hu_q24``'s one-``SMMULR``
    step (the rounded high word of ``(2 h) (u 2^16)``) equals
    ``rshift_rnd(h u, 15)``; at ``sum |p_m| = 64`` it would not.

    Raises
    ------
    ValueError
        More than :data:`MAX_POLY` terms.
    QOverflowError
        A coefficient does not fit Q7.24, or ``sum |p_m|`` (Q7.24 units)
        is not below 64.
    """
    p = np.atleast_1d(np.asarray(p, dtype=np.float64))
    p_q = np.atleast_1d(fixed.to_q(p, Q24)) if p.size else np.zeros(0, dtype=np.int64)
    if p_q.size > MAX_POLY:
        raise ValueError(f"{p_q.size} polynomial terms exceed {MAX_POLY}")
    total = int(np.sum(np.abs(p_q)))
    if total >= POLY_SUM_MAX_Q24:
        raise QOverflowError(f"sum |p_m| = {total / 2**24:.9g} is not below 64 "
                             "(eupi.h's strict bound on the polynomial)")
    return p_q.astype(np.int64), fixed.to_q(float(p0), Q24)


def quantize_eupi(params: EUPIParams) -> EUPIQ:
    """Quantize an :class:`EUPIParams` for ``piezo_eupi_init``.

    Raises
    ------
    QOverflowError
        A coefficient does not fit its format or a threshold is not below 1.
    ValueError
        ``a0`` or a slope quantizes to 0, or a count exceeds a limit.
    """
    a0 = fixed.to_q(params.a0, Q24)
    if a0 <= 0:
        raise ValueError("a0 quantizes to 0")
    cpi = quantize_bank(params.r_cpi, None, params.b, r_max_q15=Q15.max)
    upi = quantize_bank(params.r_upi, params.a_upi if params.n_upi else None,
                        params.d, r_max_q15=Q15.max) if params.n_upi else \
        PlayBankQ(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
    p_q, p0_q = quantize_poly(params.p, params.p0)
    return EUPIQ(a0, cpi, upi, p_q, p0_q)


def poly_q39(p_q24, p0_q24: int, u_q15):
    """``piezo_eupi_poly_q39``: P(u) in Q39, Horner rounded to Q7.24 per step.

    Works on an int or an int64 array of ``u_q15``.
    """
    p = [int(c) for c in np.asarray(p_q24).ravel()]
    scalar = np.ndim(u_q15) == 0
    u = int(u_q15) if scalar else np.asarray(u_q15, dtype=np.int64)
    c0 = int(p0_q24) << 15
    if not p:
        return c0 if scalar else np.full(u.shape, c0, dtype=np.int64)
    if sum(abs(c) for c in p) >= POLY_SUM_MAX_Q24:
        # the C's SMMULR step needs |h| < 2^30 (eupi.h): not a valid model
        raise QOverflowError("sum |p_m| is not below 64 (eupi.h's strict bound)")
    h = p[-1] if scalar else np.full(u.shape, p[-1], dtype=np.int64)
    for c in p[-2::-1]:
        h = fixed.rshift_rnd(h * u, 15) + c
    hu = fixed.rshift_rnd(h * u, 15)
    return hu * u + c0


def eupi_run(q: EUPIQ, u_q15, state=None, return_state: bool = False):
    """Run ``piezo_eupi_process`` on every sample of ``u_q15``.

    Parameters
    ----------
    q : EUPIQ
    u_q15 : array_like of int, shape (T,)
    state : (f_cpi, f_upi) or None
        Operator outputs to start from (None: 0, as after reset).
    return_state : bool
        Also return the state after the last sample.

    Returns
    -------
    y : ndarray of int64, shape (T,)
        q15 outputs.
    state : (f_cpi, f_upi), only if ``return_state``.
    """
    u = np.asarray(u_q15, dtype=np.int64)
    if np.any(u < Q15.min) or np.any(u > Q15.max):
        raise ValueError("input must be q15")
    cpi = PlayBankSim(q.cpi, None if state is None else state[0])
    upi = PlayBankSim(q.upi, None if state is None else state[1])
    poly = poly_q39(q.p_q24, q.p0_q24, u)
    y = np.empty(u.size, dtype=np.int64)
    for k in range(u.size):
        acc = q.a0_q24 * int(u[k]) + cpi.step(u[k]) + upi.step(u[k]) + int(poly[k])
        y[k] = fixed.sat_q15(fixed.rshift_rnd(acc, 24))
    if return_state:
        return y, (cpi.f.copy(), upi.f.copy())
    return y


def _hot_params() -> EUPIParams:
    """A model whose output saturates at both ends (gain about 1.6, offset)."""
    p = reference_params()
    return EUPIParams(a0=1.1, r_cpi=p.r_cpi, b=p.b * 3, r_upi=p.r_upi, a_upi=p.a_upi,
                      d=p.d * 2, p=p.p, p0=0.2)


def header_coef(h: CHeader, prefix: str, q: EUPIQ) -> None:
    """Declare a quantized model's coefficients as ``<prefix>_*`` arrays/defines."""
    P = prefix.upper()
    h.define(f"{P}_A0_Q24", q.a0_q24)
    h.define(f"{P}_P0_Q24", q.p0_q24)
    h.define(f"{P}_NCPI", q.cpi.r_q15.size)
    h.define(f"{P}_NUR", q.upi.r_q15.size)
    h.define(f"{P}_NUA", q.upi.a_q24.size)
    h.define(f"{P}_NP", q.p_q24.size)
    h.array(f"{prefix}_r_cpi_q15", "int32_t", q.cpi.r_q15)
    h.array(f"{prefix}_b_q24", "int32_t", q.cpi.w_q24)
    h.array(f"{prefix}_r_upi_q15", "int32_t", q.upi.r_q15)
    h.array(f"{prefix}_a_upi_q24", "int32_t", q.upi.a_q24)
    h.array(f"{prefix}_d_q24", "int32_t", q.upi.w_q24)
    h.array(f"{prefix}_p_q24", "int32_t", q.p_q24)


def signal_cases(rng: np.random.Generator) -> list[tuple[str, np.ndarray]]:
    """q15 input cases of the golden vectors (the issue's list)."""
    hi, lo = Q15.max, Q15.min
    steps = np.repeat(np.array([0, hi, lo, hi, 0, lo, hi // 2, lo, hi, hi]), 60)
    rev = np.floor(np.where(np.arange(800) % 2 == 0, hi, lo) * np.linspace(1.0, 0.0, 800) + 0.5)
    edges = np.concatenate([np.full(40, hi), np.full(40, lo), np.full(40, hi),
                            np.floor(np.linspace(lo, hi, 300) + 0.5), np.full(20, lo)])
    return [
        ("random", rng.integers(lo, hi + 1, 1000)),
        ("realistic", np.floor(realistic_drive(2000) * 32768.0 + 0.5)),
        ("steps", steps),
        ("reversals", rev),
        ("constant", np.full(300, 12123)),
        ("edges", edges),
    ]


def c_header() -> str:
    """Golden vectors of the EUPI model: the reference model on every case,
    a saturating model on the edges, and the realistic run in two blocks."""
    q = quantize_eupi(reference_params())
    hot = quantize_eupi(_hot_params())
    rng = np.random.default_rng(9)
    h = CHeader("eupi")
    header_coef(h, "golden_eupi", q)
    header_coef(h, "golden_eupi_hot", hot)
    cases = signal_cases(rng)
    for name, u in cases:
        u = np.asarray(u, dtype=np.int64)
        h.comment(f"reference model, {name} input")
        h.define(f"GOLDEN_EUPI_{name.upper()}_N", u.size)
        h.array(f"golden_eupi_{name}_u", "int16_t", u)
        h.array(f"golden_eupi_{name}_y", "int16_t", eupi_run(q, u))
    edges = np.asarray(dict(cases)["edges"], dtype=np.int64)
    y_hot = eupi_run(hot, edges)
    assert y_hot.max() == Q15.max and y_hot.min() == Q15.min, "hot model must saturate"
    h.comment("saturating model, edges input: output clamped at both ends")
    h.array("golden_eupi_hot_edges_y", "int16_t", y_hot)
    u = np.asarray(dict(cases)["realistic"], dtype=np.int64)
    half = u.size // 2
    y1, st = eupi_run(q, u[:half], return_state=True)
    y2 = eupi_run(q, u[half:], state=st)
    h.comment("realistic input in two blocks, golden state carried over")
    h.define("GOLDEN_EUPI_SPLIT_HALF", half)
    h.array("golden_eupi_split_y", "int16_t", np.concatenate([y1, y2]))
    return str(h)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, y_float, y_fixed_q15) of the reference model on a realistic drive.

    Both sides get the same q15 drive; the float side uses the unquantized
    coefficients (:func:`piezoctl.models.eupi.eupi_model`).
    """
    params = reference_params()
    u_q = np.floor(realistic_drive(20000) * 32768.0 + 0.5).astype(np.int64)
    y_fixed = eupi_run(quantize_eupi(params), u_q)
    y_float = eupi_model(u_q / 32768.0, params)
    return [("reference EUPI, realistic drive", y_float, y_fixed)]
