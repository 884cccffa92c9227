"""Golden vectors for the shared primitives of ``fixed_q.h``."""

from __future__ import annotations

import numpy as np

from .. import fixed
from .export import CHeader


def c_header() -> str:
    rng = np.random.default_rng(2)
    # Products of q15 and q24 across the full range, ties included.
    a = np.concatenate([[-32768, 32767, 0, 1, -1, 16384, -16384],
                        rng.integers(-32768, 32768, 500)])
    b = np.concatenate([[-(1 << 31), (1 << 31) - 1, 1 << 23, -(1 << 23), 1 << 24, 3, -3],
                        rng.integers(-(1 << 31), 1 << 31, 500)])
    mul = np.array([fixed.mul_q15_q24(int(x), int(y)) for x, y in zip(a, b)])
    # Round-half-up shifts, including exact ties of both signs.
    x = np.concatenate([[-3, -2, -1, 0, 1, 2, 3, -5, 5, -(1 << 40) - (1 << 9)],
                        rng.integers(-(1 << 50), 1 << 50, 300)])
    s = np.concatenate([[1] * 9 + [10], rng.integers(1, 40, 300)])
    rs = np.array([fixed.rshift_rnd(int(v), int(k)) for v, k in zip(x, s)])
    h = CHeader("fixed_q")
    h.define("GOLDEN_MUL_N", len(a))
    h.array("golden_mul_a_q15", "int32_t", a)
    h.array("golden_mul_b_q24", "int32_t", b)
    h.array("golden_mul_out_q15", "int16_t", mul)
    h.define("GOLDEN_RSHIFT_N", len(x))
    h.array("golden_rshift_x", "int64_t", x)
    h.array("golden_rshift_s", "uint8_t", s)
    h.array("golden_rshift_out", "int64_t", rs)
    return str(h)
