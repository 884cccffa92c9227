"""Fixed-point primitives shared by every golden model and the quantizer.

The formats and the one rounding rule are the firmware's
(``firmware/core/fixed_q.h``); see ``docs/fixed-point.md``.

- ``q15``: int16, Q0.15, signals normalized to full scale, [-1, 1 - 2**-15].
- ``q24``: int32, Q7.24, gains, weights, densities, [-128, 128 - 2**-24].
- ``q16``: int32, Q15.16, slopes and scales.

Rounding: a right shift by ``s`` adds ``2**(s-1)`` then floors, i.e. round half
toward +infinity. Float-to-Q conversion uses the same rule:
``floor(x * 2**f + 0.5)``. Conversions raise :class:`QOverflowError` when the
value does not fit, instead of wrapping or clamping silently.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "QFormat", "Q15", "Q24", "Q16", "Q15W", "QOverflowError",
    "rshift_rnd", "sat_q15", "sat_i32", "mul_q15_q24", "to_q", "from_q",
]


class QOverflowError(ValueError):
    """A value does not fit the fixed-point format it is converted to."""


class QFormat:
    """A signed fixed-point format: ``bits``-wide container, ``frac`` fraction bits."""

    def __init__(self, name: str, bits: int, frac: int):
        self.name = name
        self.bits = bits
        self.frac = frac
        self.min = -(1 << (bits - 1))
        self.max = (1 << (bits - 1)) - 1
        self.one = 1 << frac

    def __repr__(self) -> str:
        return f"QFormat({self.name!r}, bits={self.bits}, frac={self.frac})"


Q15 = QFormat("q15", 16, 15)
Q24 = QFormat("q24", 32, 24)
Q16 = QFormat("q16", 32, 16)
Q15W = QFormat("q15 in int32", 32, 15)  # q15-scaled values that may exceed 1 FS


def rshift_rnd(x, s: int):
    """Round-half-up arithmetic right shift by ``s`` bits (ints or int64 arrays)."""
    if isinstance(x, np.ndarray):
        return (x.astype(np.int64) + np.int64(1 << (s - 1))) >> np.int64(s)
    return (int(x) + (1 << (s - 1))) >> s


def sat_q15(x):
    """Clamp to the q15 range [-32768, 32767]."""
    if isinstance(x, np.ndarray):
        return np.clip(x, Q15.min, Q15.max).astype(np.int64)
    return max(Q15.min, min(Q15.max, int(x)))


def sat_i32(x):
    """Clamp to the int32 range."""
    if isinstance(x, np.ndarray):
        return np.clip(x, -(1 << 31), (1 << 31) - 1).astype(np.int64)
    return max(-(1 << 31), min((1 << 31) - 1, int(x)))


def mul_q15_q24(a_q15, b_q24):
    """q15 * q24 -> q15, rounded and saturated, as ``piezo_mul_q15_q24``."""
    return sat_q15(rshift_rnd(a_q15 * b_q24, 24))


def to_q(x, fmt: QFormat, *, clamp: bool = False):
    """Convert floats to ``fmt`` with the rounding rule ``floor(x * 2**f + 0.5)``.

    Parameters
    ----------
    x : float or array_like of float
        Values in real units of the format (e.g. normalized full scale for q15).
    fmt : QFormat
        Target format.
    clamp : bool
        Clamp out-of-range values instead of raising.

    Returns
    -------
    int or numpy.ndarray of int64

    Raises
    ------
    QOverflowError
        If a value is outside the format's range (and ``clamp`` is False) or not finite.
    """
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise QOverflowError(f"non-finite value cannot be converted to {fmt.name}")
    q = np.floor(arr * float(fmt.one) + 0.5)
    if clamp:
        q = np.clip(q, fmt.min, fmt.max)
    elif np.any(q < fmt.min) or np.any(q > fmt.max):
        worst = float(arr.flat[int(np.argmax(np.abs(arr)))])
        raise QOverflowError(
            f"value {worst:g} does not fit {fmt.name} "
            f"[{fmt.min / fmt.one:g}, {fmt.max / fmt.one:g}]")
    q = q.astype(np.int64)
    if np.ndim(x) == 0:
        return int(q)
    return q


def from_q(q, fmt: QFormat):
    """Convert fixed-point integers of ``fmt`` to float64."""
    return np.asarray(q, dtype=np.float64) / float(fmt.one)


assert math.floor(-2.5 + 0.5) == -2  # documents the half-up tie rule
