"""Bit-exact twin of ``firmware/core/fir.h``: the dynamics-inverse FIR of the feedforward path.

``y(t) = sat_q15(rshift_rnd(sum_k h_k x(t - k d), 13))``: input and output q15,
taps q13 (Q2.13, int16, 8192 = 1), spacing ``d`` ticks (0 reads as 1), one
rounding (round half toward +infinity) and one saturation. The history starts
full of ``x0`` (``piezo_fir_reset``). The design of the taps is
``piezoctl.calibrate.dyninv``; :func:`quantize_taps` is its float-to-q13 step.
"""

from __future__ import annotations

import numpy as np

from .. import fixed
from .export import CHeader

__all__ = ["FRAC", "MAX_TAPS", "MAX_SPACING", "fir_q13", "quantize_taps", "c_header"]

FRAC = 13
MAX_TAPS = 32      # interface.toml dyninv_q13's count (fir.h PIEZO_FIR_MAX_TAPS)
MAX_SPACING = 8    # fir.h PIEZO_FIR_MAX_SPACING; the register dyninv_ticks refuses more


def _max_taps() -> int:
    from ..interface import HOLDING_REGISTERS
    return HOLDING_REGISTERS["dyninv_q13"][2]


def fir_q13(x_q15, h_q13, spacing: int = 1, x0_q15: int | None = None) -> np.ndarray:
    """The firmware's filter on a whole input sequence.

    Parameters
    ----------
    x_q15 : array of int
        Input samples, q15 (the shaped early reference), oldest first.
    h_q13 : array of int
        Taps, q13, newest sample first (at most :data:`MAX_TAPS`, each in int16).
    spacing : int
        Ticks between taps, 0..:data:`MAX_SPACING` (0 reads as 1).
    x0_q15 : int, optional
        The value the history starts filled with (default: the first input).

    Returns
    -------
    numpy.ndarray of int64
        Output samples, q15.
    """
    x = np.asarray(x_q15, dtype=np.int64)
    h = np.asarray(h_q13, dtype=np.int64)
    if h.size > _max_taps() or not 0 <= spacing <= MAX_SPACING:
        raise ValueError(f"at most {_max_taps()} taps and a spacing of 0..{MAX_SPACING}")
    if np.any(h < -32768) or np.any(h > 32767) or np.any(x < -32768) or np.any(x > 32767):
        raise ValueError("taps and samples are int16")
    d = max(1, int(spacing))
    pad = (h.size - 1) * d if h.size else 0
    x0 = int(x[0]) if x0_q15 is None and x.size else int(x0_q15 or 0)
    xp = np.concatenate([np.full(pad, x0, dtype=np.int64), x])
    acc = np.zeros(x.size, dtype=np.int64)
    for k in range(h.size):
        acc += h[k] * xp[pad - k * d: pad - k * d + x.size]
    return np.clip(fixed.rshift_rnd(acc, FRAC), -32768, 32767)


def quantize_taps(h) -> list[int]:
    """Float taps -> q13 with the rounding rule ``floor(x 2^13 + 0.5)``; raises
    :class:`piezoctl.fixed.QOverflowError` for a tap outside [-4, 4 - 2^-13]."""
    out = []
    for v in np.asarray(h, dtype=float):
        q = int(np.floor(v * (1 << FRAC) + 0.5))
        if not -32768 <= q <= 32767:
            raise fixed.QOverflowError(f"tap {v:.4g} does not fit q13 ([-4, 4))")
        out.append(q)
    return out


def c_header() -> str:
    """Golden vectors: random references and taps, every spacing, saturation on both ends."""
    rng = np.random.default_rng(15)
    h = CHeader("fir")
    cases = []
    # a smooth random reference through a realistic inverse-like filter (a large centre tap)
    for n_taps, d in ((32, 1), (32, 8), (7, 3), (1, 1), (32, 0), (16, 5)):
        taps = rng.integers(-2000, 2000, n_taps)
        taps[n_taps // 2] += 8192
        x = np.cumsum(rng.integers(-900, 900, 700))
        x = np.clip(x - x.mean(), -32768, 32767)
        cases.append((taps, d, x))
    # extremes: full-scale taps and inputs (|acc| at its bound 2^35), saturating both ways
    cases.append((np.full(32, -32768), 1, rng.choice([-32768, 32767], 400)))
    cases.append((np.full(32, 32767), 2, rng.choice([-32768, 32767, 0], 400)))
    cases.append((rng.integers(-32768, 32768, 32), 7, rng.integers(-32768, 32768, 400)))
    # ties of the rounding: taps of 4096 (1/2) on odd inputs
    cases.append((np.array([4096, 4096]), 1, rng.integers(-5, 6, 200)))
    h.define("GOLDEN_FIR_CASES", len(cases))
    offs = [0]
    for taps, d, x in cases:
        offs.append(offs[-1] + x.size)
    h.array("golden_fir_n_taps", "uint8_t", [c[0].size for c in cases])
    h.array("golden_fir_spacing", "uint8_t", [c[1] for c in cases])
    h.array("golden_fir_x_off", "uint32_t", offs)
    taps_all = np.zeros((len(cases), _max_taps()), dtype=np.int64)
    for i, (taps, _, _) in enumerate(cases):
        taps_all[i, :taps.size] = taps
    h.array("golden_fir_h_q13", "int16_t", taps_all.ravel())
    h.array("golden_fir_x_q15", "int16_t", np.concatenate([c[2] for c in cases]))
    h.array("golden_fir_y_q15", "int16_t", np.concatenate([fir_q13(x, taps, d) for taps, d, x in cases]))
    return str(h)
