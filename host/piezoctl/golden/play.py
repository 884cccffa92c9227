"""Bit-exact golden model of ``firmware/core/play.c`` (CPI/UPI play operator bank).

Integers are numpy int64 throughout; every value the C kernel forms fits int64
by the bounds of ``play.h`` ("Scaling and overflow"), which
:func:`quantize_bank` enforces on the coefficients.

Formats: inputs, thresholds and operator outputs are q15-scaled integers in an
int32 container (``Q15W``, 32768 = 1.0 full scale, bounded by ``WIDE_MAX``);
slopes and weights are Q7.24. The weighted sum is Q39.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q24, QFormat, QOverflowError
from ..models.play import play_outputs
from .export import CHeader

__all__ = [
    "Q15W", "WIDE_MAX", "MAX_OPS", "PlayBankQ", "PlayBankSim", "quantize_bank", "play_bank_run",
    "realistic_drive", "reference_banks", "c_header", "error_report",
]

Q15W = QFormat("q15 in int32", 32, 15)
WIDE_MAX = 1 << 20          # PIEZO_PLAY_WIDE_MAX_Q15
MAX_OPS = 256               # PIEZO_PLAY_MAX_OPS


@dataclass(frozen=True)
class PlayBankQ:
    """Quantized coefficients of one bank (``struct piezo_play_coef``).

    ``a_q24`` is empty for a classical bank. ``w_q24`` is row-major (i, j).
    """

    r_q15: np.ndarray
    a_q24: np.ndarray
    w_q24: np.ndarray

    @property
    def n_ops(self) -> int:
        return self.r_q15.size * max(1, self.a_q24.size)

    def per_op(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Threshold and slope of every operator (slope None for classical)."""
        na = self.a_q24.size
        if na == 0:
            return self.r_q15, None
        return np.repeat(self.r_q15, na), np.tile(self.a_q24, self.r_q15.size)


def quantize_bank(r, a, w, *, r_max_q15: int = WIDE_MAX) -> PlayBankQ:
    """Quantize a bank's float coefficients and check the C kernel's ranges.

    Parameters
    ----------
    r : array_like, shape (n_r,)
        Thresholds [FS], ``>= 0``, non-decreasing.
    a : array_like, shape (n_a,), or None
        Slopes (> 0) of an unparallel grid; None or empty for classical.
    w : array_like, shape (n_r * max(n_a, 1),) or (n_r, n_a)
        Weights, row-major (i, j).
    r_max_q15 : int
        Largest threshold accepted (q15 units).

    Raises
    ------
    QOverflowError
        A value does not fit its format, or a threshold exceeds ``r_max_q15``.
    ValueError
        A negative threshold, decreasing thresholds, a slope that quantizes to
        0 or below, too many operators, or mismatched lengths.
    """
    r_q = np.atleast_1d(fixed.to_q(np.atleast_1d(np.asarray(r, dtype=np.float64)), Q15W))
    a_arr = np.zeros(0) if a is None else np.atleast_1d(np.asarray(a, dtype=np.float64))
    a_q = np.atleast_1d(fixed.to_q(a_arr, Q24)) if a_arr.size else np.zeros(0, dtype=np.int64)
    w_q = np.atleast_1d(fixed.to_q(np.asarray(w, dtype=np.float64).ravel(), Q24))
    n_ops = r_q.size * max(1, a_q.size)
    if w_q.size != n_ops:
        raise ValueError(f"need {n_ops} weights, got {w_q.size}")
    if n_ops > MAX_OPS:
        raise ValueError(f"{n_ops} operators exceed the bank's {MAX_OPS}")
    if np.any(r_q < 0) or np.any(np.diff(r_q) < 0):
        raise ValueError("thresholds must be >= 0 and non-decreasing")
    if np.any(r_q > r_max_q15):
        raise QOverflowError(f"threshold {r_q.max() / 32768:g} exceeds {r_max_q15 / 32768:g} FS")
    if np.any(a_q <= 0):
        raise ValueError("slopes must quantize to > 0")
    return PlayBankQ(r_q.astype(np.int64), a_q.astype(np.int64), w_q.astype(np.int64))


class PlayBankSim:
    """State of one bank instance (``struct piezo_play``): :meth:`step` is
    ``piezo_play_process``.

    Parameters
    ----------
    bank : PlayBankQ
    f0 : array_like of int, shape (n_ops,), or None
        Operator outputs before the first sample (None: 0, as after reset).
    """

    def __init__(self, bank: PlayBankQ, f0=None):
        self.bank = bank
        self.r, self.a = bank.per_op()
        n = self.r.size
        # init: c_ij = rshift_rnd(a_j r_i, 24) (q15, |c| < 2^27), so that the upper
        # branch rshift_rnd(a_j u, 24) + c_ij has one rounding per slope and sample
        self.c = None if self.a is None else fixed.rshift_rnd(self.a * self.r, 24)
        self.f = np.zeros(n, dtype=np.int64) if f0 is None else np.array(f0, dtype=np.int64).reshape(n)

    def step(self, u: int) -> int:
        """Update every operator with ``u`` (q15-scaled); return the Q39 weighted sum."""
        u = int(u)
        if abs(u) > WIDE_MAX:
            raise ValueError("input beyond the bank's wide range")
        hi = u + self.r if self.a is None else fixed.rshift_rnd(self.a * u, 24) + self.c
        self.f = np.maximum(u - self.r, np.minimum(hi, self.f))
        return int(self.f @ self.bank.w_q24) if self.f.size else 0


def play_bank_run(bank: PlayBankQ, u_q15, f0=None) -> tuple[np.ndarray, np.ndarray]:
    """Run ``piezo_play_process`` on every sample of ``u_q15``.

    Parameters
    ----------
    bank : PlayBankQ
    u_q15 : array_like of int, shape (T,)
        Inputs, q15-scaled, ``|u| <= WIDE_MAX``.
    f0 : array_like of int, shape (n_ops,), or None
        Operator outputs before the first sample (None: 0, as after reset);
        pass the last row of a previous run to continue it.

    Returns
    -------
    f : ndarray of int64, shape (T, n_ops)
        Operator outputs after each sample (q15-scaled).
    acc : ndarray of int64, shape (T,)
        The weighted sum returned by process, Q39.
    """
    sim = PlayBankSim(bank, f0)
    u = np.asarray(u_q15, dtype=np.int64)
    out = np.empty((u.size, sim.r.size), dtype=np.int64)
    acc = np.empty(u.size, dtype=np.int64)
    for k in range(u.size):
        acc[k] = sim.step(u[k])
        out[k] = sim.f
    return out, acc


# ------------------------------------------------------------------ signals


def realistic_drive(n: int = 4000, fs: float = 10e3, amp: float = 0.9, seed: int = 7) -> np.ndarray:
    """A drive like a scan: decaying 10 Hz sine with a 73 Hz minor loop and noise [FS]."""
    t = np.arange(n) / fs
    rng = np.random.default_rng(seed)
    env = 0.55 + 0.45 * np.cos(2 * np.pi * 1.3 * t)
    u = amp * (0.85 * env * np.sin(2 * np.pi * 10 * t) + 0.12 * np.sin(2 * np.pi * 73 * t))
    u += 0.003 * rng.standard_normal(n)
    return np.clip(u, -1.0, 1.0 - 2.0 ** -15)


def reference_banks() -> tuple[tuple, tuple]:
    """Float coefficients of the reference CPI bank (10) and UPI grid (10 x 3).

    Returns ``((r, None, b), (r_u, a_u, d))``.
    """
    rng = np.random.default_rng(11)
    r = np.linspace(0.0, 0.9, 10)
    b = np.round(rng.uniform(0.01, 0.08, 10), 6)
    ru = np.linspace(0.0, 0.9, 10)
    au = np.array([0.6, 1.0, 1.45])
    d = np.round(rng.uniform(0.0, 0.012, (10, 3)), 6)
    return (r, None, b), (ru, au, d)


def _cases(rng: np.random.Generator, fs_max: int) -> list[tuple[str, np.ndarray]]:
    """Input cases for golden vectors, q15-scaled, bounded by ``fs_max``."""
    lo, hi = -fs_max, fs_max - 1
    steps = np.repeat(np.array([0, hi, lo, hi, 0, lo, hi // 2, lo, hi, hi]), 60)
    rev = np.where(np.arange(800) % 2 == 0, hi, lo) * np.linspace(1.0, 0.0, 800)
    edges = np.concatenate([np.full(50, hi), np.full(50, lo), np.full(50, hi),
                            np.linspace(lo, hi, 300), np.full(25, lo)])
    scale = fs_max / 32768.0
    real = realistic_drive(1500) * 32768.0 * scale
    return [
        ("random", rng.integers(lo, hi + 1, 1000)),
        ("realistic", np.floor(real + 0.5)),
        ("steps", steps),
        ("reversals", np.floor(rev + 0.5)),
        ("constant", np.full(300, int(0.37 * fs_max))),
        ("edges", np.floor(edges + 0.5)),
    ]


def c_header() -> str:
    """Golden vectors of the play bank: a classical bank fed q15 and wide inputs,
    an unparallel grid, every operator output and the weighted sum of every sample.
    """
    (r, _, b), (ru, au, d) = reference_banks()
    cpi = quantize_bank(r, None, b)
    upi = quantize_bank(ru, au, d)
    # Classical bank with wide thresholds and signed weights, as the inverse uses.
    wide = quantize_bank(np.linspace(0.0, 3.5, 8), None, np.linspace(-0.6, 0.3, 8))
    rng = np.random.default_rng(5)
    h = CHeader("play")
    for name, bank in (("cpi", cpi), ("upi", upi), ("wide", wide)):
        h.define(f"GOLDEN_PLAY_{name.upper()}_NR", bank.r_q15.size)
        h.define(f"GOLDEN_PLAY_{name.upper()}_NA", bank.a_q24.size)
        h.array(f"golden_play_{name}_r_q15", "int32_t", bank.r_q15)
        h.array(f"golden_play_{name}_a_q24", "int32_t", bank.a_q24)
        h.array(f"golden_play_{name}_w_q24", "int32_t", bank.w_q24)
    names = []
    for bank_name, bank, fs_max in (("cpi", cpi, 32768), ("upi", upi, 32768),
                                    ("wide", wide, WIDE_MAX)):
        for case, u in _cases(rng, fs_max):
            u = np.asarray(u, dtype=np.int64)
            f, acc = play_bank_run(bank, u)
            tag = f"{bank_name}_{case}"
            names.append(tag)
            h.comment(f"{bank_name} bank, {case} input")
            h.define(f"GOLDEN_PLAY_{tag.upper()}_N", u.size)
            h.array(f"golden_play_{tag}_u", "int32_t", u)
            h.array(f"golden_play_{tag}_acc", "int64_t", acc)
            # every operator's output (row-major sample, operator) of a prefix
            nf = min(u.size, 200)
            h.define(f"GOLDEN_PLAY_{tag.upper()}_NF", nf)
            h.array(f"golden_play_{tag}_f", "int32_t", f[:nf].ravel())
    # The realistic UPI run split in two: the golden model continues from the
    # state at the split, the C test runs on without reset.
    u = np.floor(realistic_drive(2000) * 32768.0 + 0.5).astype(np.int64)
    half = u.size // 2
    f1, acc1 = play_bank_run(upi, u[:half])
    _, acc2 = play_bank_run(upi, u[half:], f0=f1[-1])
    h.comment("unparallel bank, realistic input in two blocks")
    h.define("GOLDEN_PLAY_SPLIT_N", u.size)
    h.define("GOLDEN_PLAY_SPLIT_HALF", half)
    h.array("golden_play_split_u", "int32_t", u)
    h.array("golden_play_split_acc", "int64_t", np.concatenate([acc1, acc2]))
    return str(h)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, y_float, y_fixed_q15) of the reference banks on a realistic drive.

    The output compared is the weighted sum of each bank, rounded to q15 with
    the rounding rule. Both sides see the same q15 input; the float side uses
    the unquantized coefficients.
    """
    (r, _, b), (ru, au, d) = reference_banks()
    u_q = np.floor(realistic_drive(20000) * 32768.0 + 0.5).astype(np.int64)
    u = u_q / 32768.0
    out = []
    for name, rr, aa, ww in (("cpi bank", r, None, b), ("upi bank", ru, au, d)):
        bank = quantize_bank(rr, aa, ww)
        _, acc = play_bank_run(bank, u_q)
        y_fixed = fixed.rshift_rnd(acc, 24)
        rf = rr if aa is None else np.repeat(rr, len(aa))
        af = 1.0 if aa is None else np.tile(aa, len(rr))
        y_float = play_outputs(u, rf, af) @ np.ravel(ww)
        out.append((f"{name}, realistic drive", y_float, y_fixed))
    return out
