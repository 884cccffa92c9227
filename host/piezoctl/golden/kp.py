"""Bit-exact golden model of ``firmware/core/kp.c`` (KP operators and model).

Integers only (numpy int64 and Python ints), computing exactly what the C
kernel computes; see ``kp.h`` and ``docs/kernels-kp.md`` for formats,
rounding and the reset state. :func:`quantize_grid` and
:func:`quantize_density` turn the float reference's parameters
(``piezoctl.models.kp``) into the kernel's coefficients and raise
:class:`piezoctl.fixed.QOverflowError` when a value does not fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q16, Q24, QOverflowError
from ..models import kp as fkp
from ..models.kp import _runs
from .export import CHeader

__all__ = [
    "KPGridQ", "MAX_OPS", "xsat_for", "check_grid", "quantize_grid", "quantize_density",
    "ridge_q", "kp_outputs_q", "kp_process_q", "demo_density", "realistic_signal",
    "emit_grid", "golden_cases", "c_header", "error_report", "error_bound_lsb",
]

MAX_OPS = 4096  # PIEZO_KP_MAX_OPS


@dataclass(frozen=True)
class KPGridQ:
    """The C ``struct piezo_kp_grid``: thresholds and ridge in integers."""

    n1: np.ndarray   # int64 q15, falling thresholds
    n2: np.ndarray   # int64 q15, rising thresholds
    nmin: int        # q15, input after reset
    rmax: int        # q15, ridge height 1..32767
    slope: int       # q16, ridge slope rmax / s
    xsat: int        # smallest x >= 1 with rshift_rnd(x * slope, 16) >= rmax

    @property
    def N(self) -> int:
        return int(self.n1.size)


def xsat_for(slope_q16: int, rmax_q15: int) -> int:
    """Smallest ``x >= 1`` with ``rshift_rnd(x * slope, 16) >= rmax``."""
    slope_q16, rmax_q15 = int(slope_q16), int(rmax_q15)
    if slope_q16 < 1 or rmax_q15 < 1:
        raise ValueError("slope and rmax must be >= 1")
    # rnd(x*s) >= r  <=>  x*s + 2^15 >= r*2^16  <=>  x >= ceil((r*2^16 - 2^15) / s)
    x = max(1, -((-(rmax_q15 * 65536 - 32768)) // slope_q16))
    assert fixed.rshift_rnd(x * slope_q16, 16) >= rmax_q15
    assert x == 1 or fixed.rshift_rnd((x - 1) * slope_q16, 16) < rmax_q15
    return x


def check_grid(g: KPGridQ) -> None:
    """Raise ValueError where ``piezo_kp_grid_check`` would refuse the grid."""
    if g.n1.shape != g.n2.shape or g.n1.ndim != 1:
        raise ValueError("n1 and n2 must be 1-D arrays of one length")
    if not 1 <= g.N <= MAX_OPS:
        raise ValueError(f"n_ops must be in 1..{MAX_OPS}, got {g.N}")
    for name, arr in (("n1", g.n1), ("n2", g.n2)):
        if arr.min() < Q15.min or arr.max() > Q15.max:
            raise QOverflowError(f"{name} outside q15")
    if not Q15.min <= g.nmin <= Q15.max:
        raise QOverflowError("nmin outside q15")
    if np.any(g.n1 > g.n2):
        raise ValueError("thresholds out of order: need n1 <= n2")
    if not 1 <= g.rmax <= Q15.max:
        raise ValueError(f"rmax must be in 1..32767, got {g.rmax}")
    if not 1 <= g.slope <= Q16.max:
        raise ValueError(f"slope_q16 must be in 1..{Q16.max}, got {g.slope}")
    if g.xsat != xsat_for(g.slope, g.rmax):
        raise ValueError("xsat does not match slope and rmax")


def quantize_grid(grid: fkp.KPGrid) -> KPGridQ:
    """Coefficients of the C grid from a float :class:`~piezoctl.models.kp.KPGrid`.

    Thresholds and ``nmin`` round to q15, the slope ``nmax / s`` to q16, all
    with :func:`piezoctl.fixed.to_q` (raising on overflow). The ridge height
    ``nmax`` rounds to q15 too, except that a height that rounds to exactly
    1.0 (32768, one past the q15 top) is stored as 32767, like any q15 signal
    at full scale.
    """
    rq = int(np.floor(grid.nmax * Q15.one + 0.5))
    if rq == Q15.one:
        rq = Q15.max
    elif not 1 <= rq <= Q15.max:
        raise QOverflowError(f"ridge height nmax={grid.nmax:g} does not fit q15 (0, 1]")
    slope = fixed.to_q(grid.slope, Q16)
    if slope < 1:
        raise QOverflowError(f"ridge slope {grid.slope:g} rounds to 0 in q16")
    g = KPGridQ(n1=fixed.to_q(grid.n1, Q15), n2=fixed.to_q(grid.n2, Q15),
                nmin=fixed.to_q(grid.nmin, Q15), rmax=rq, slope=slope,
                xsat=xsat_for(slope, rq))
    check_grid(g)
    return g


def quantize_density(w) -> np.ndarray:
    """Density to q24 (raises :class:`QOverflowError` outside [-128, 128))."""
    return fixed.to_q(np.asarray(w, dtype=np.float64).ravel(), Q24)


def ridge_q(x, g: KPGridQ) -> np.ndarray:
    """``piezo_kp_ridge_q15``: ``min(rmax, rshift_rnd(max(x, 0) * slope, 16))``."""
    x = np.asarray(x, dtype=np.int64)
    mid = fixed.rshift_rnd(np.clip(x, 0, g.xsat) * np.int64(g.slope), 16)
    return np.where(x <= 0, 0, np.where(x >= g.xsat, g.rmax, mid)).astype(np.int64)


def kp_outputs_q(u_q15, g: KPGridQ, psi0=None, u_prev: int | None = None) -> np.ndarray:
    """Operator outputs ``psi_q15`` (T, N) for inputs ``u_q15``, as the C kernel.

    Monotone runs are vectorized (``ridge_q`` is non-decreasing, so the
    per-sample recursion and the run formula agree exactly).
    """
    u = np.asarray(u_q15, dtype=np.int64).ravel()
    psi = np.zeros(g.N, dtype=np.int64) if psi0 is None else np.asarray(psi0, dtype=np.int64).copy()
    up = g.nmin if u_prev is None else int(u_prev)
    out = np.empty((u.size, g.N), dtype=np.int64)
    for k0, k1, d in _runs(u, up):
        seg = u[k0:k1, None]
        if d > 0:
            np.maximum(psi, ridge_q(seg - g.n2, g), out=out[k0:k1])
        elif d < 0:
            np.minimum(psi, ridge_q(seg - g.n1, g), out=out[k0:k1])
        else:
            out[k0:k1] = psi
        psi = out[k1 - 1]
    return out


def kp_process_q(u_q15, g: KPGridQ, w_q24, psi0=None, u_prev: int | None = None):
    """``piezo_kp_process`` over a signal: returns ``(y_q15, psi_q15)``.

    ``y[k] = sat_q15(rshift_rnd(sum_j psi_j[k] * w_j, 24))``; ``psi`` is the
    (T, N) operator trajectory.
    """
    psi = kp_outputs_q(u_q15, g, psi0, u_prev)
    acc = psi @ np.asarray(w_q24, dtype=np.int64)   # exact: |acc| < 2^58
    return fixed.sat_q15(fixed.rshift_rnd(acc, 24)), psi


# ---------------------------------------------------------------- test signals

def demo_density(grid: fkp.KPGrid) -> np.ndarray:
    """A plausible piezo density: a smooth bump near the diagonal, summing to 1."""
    wid = grid.n2 - grid.n1
    cen = 0.5 * (grid.n1 + grid.n2)
    span = grid.nmax - grid.nmin
    w = np.exp(-(wid / (0.35 * span)) ** 2) * np.exp(-(cen / (0.6 * span)) ** 2) + 0.02
    return w / w.sum()


def realistic_signal(T: int, seed: int = 0, fs: float = 10e3) -> np.ndarray:
    """A drive as a stage sees it [q15]: decaying sine sweep plus a faster tone and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fs
    env = 0.95 * np.exp(-t / (0.6 * T / fs))
    f = 15.0 + 60.0 * t / max(t[-1], 1e-9)
    u = env * np.sin(2 * np.pi * np.cumsum(f) / fs) + 0.04 * np.sin(2 * np.pi * 230 * t)
    u += 2e-4 * rng.standard_normal(T)
    return fixed.to_q(np.clip(u, -1.0, 1.0 - 2.0 ** -15), Q15)


def _steps(T: int) -> np.ndarray:
    levels = [-32768, 32767, -32768, 0, 32767, 0, -32768, 16384, -16384, 32767]
    hold = T // len(levels)
    return np.repeat(np.array(levels, dtype=np.int64), hold)


def _alternating(T: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    amp = np.linspace(100, 32000, T)
    u = amp * np.where(np.arange(T) % 2 == 0, 1.0, -1.0) + rng.integers(-50, 51, T)
    return np.clip(np.round(u), Q15.min, Q15.max).astype(np.int64)


def golden_cases(T: int = 2000) -> dict[str, np.ndarray]:
    """The golden input signals [q15] shared by the KP, RKP and DCC vectors."""
    rng = np.random.default_rng(7)
    const = np.concatenate([np.full(T // 2, 12345), np.full(T - T // 2, -2000)]).astype(np.int64)
    edges = np.tile(np.array([-32768, -32768, 32767, 32767, -32767, 32766, 0, -32768, 32767],
                             dtype=np.int64), T // 9 + 1)[:T]
    return {
        "random": rng.integers(Q15.min, Q15.max + 1, T).astype(np.int64),
        "realistic": realistic_signal(T, seed=3),
        "steps": _steps(T),
        "alternating": _alternating(T, seed=5),
        "constant": const,
        "edges": edges,
    }


def emit_grid(h: CHeader, prefix: str, g: KPGridQ) -> None:
    """Write a grid as ``<prefix>_N1``... arrays and defines for the C tests."""
    h.define(f"{prefix}_NOPS", g.N)
    h.define(f"{prefix}_NMIN", g.nmin)
    h.define(f"{prefix}_RMAX", g.rmax)
    h.define(f"{prefix}_SLOPE", g.slope)
    h.define(f"{prefix}_XSAT", g.xsat)
    h.array(f"{prefix}_n1", "int16_t", g.n1)
    h.array(f"{prefix}_n2", "int16_t", g.n2)


def std_grid() -> tuple[fkp.KPGrid, KPGridQ, np.ndarray, np.ndarray]:
    """The reference plane of the vectors: L = 10 (55 operators), demo density."""
    grid = fkp.kp_grid(10)
    w = demo_density(grid)
    return grid, quantize_grid(grid), w, quantize_density(w)


def edge_grid() -> tuple[KPGridQ, np.ndarray]:
    """Extreme coefficients: thresholds at the q15 ends, a step-like ridge and
    weights at the q24 ends, so that the output saturates both ways."""
    n1 = np.array([-32768, -32768, -32768, 0, 0, 32767, -1, -32768, 100, -20000], dtype=np.int64)
    n2 = np.array([-32768, 32767, 0, 0, 32767, 32767, 0, -32767, 30000, 20000], dtype=np.int64)
    slope = (1 << 31) - 1
    g = KPGridQ(n1=n1, n2=n2, nmin=-32768, rmax=32767, slope=slope, xsat=xsat_for(slope, 32767))
    w = np.array([-(1 << 31), -(1 << 31), -(1 << 31), (1 << 31) - 1, -(1 << 31),
                  1 << 30, (1 << 31) - 1, 12345678, -987654321, (1 << 31) - 1], dtype=np.int64)
    check_grid(g)
    return g, w


def flat_grid() -> tuple[KPGridQ, np.ndarray]:
    """The flattest ridge (slope 1 LSB q16, never saturating), small rmax elsewhere."""
    grid = fkp.kp_grid(4)
    base = quantize_grid(grid)
    g = KPGridQ(n1=base.n1, n2=base.n2, nmin=-20000, rmax=32767, slope=1, xsat=xsat_for(1, 32767))
    check_grid(g)
    return g, np.full(g.N, 1 << 30, dtype=np.int64)


def c_header() -> str:
    h = CHeader("kp")
    h.comment("KP golden vectors: grids, densities, inputs and outputs (q15).")
    _, gs, _, ws = std_grid()
    ge, we = edge_grid()
    gf, wf = flat_grid()
    for name, g, w in (("kp_std", gs, ws), ("kp_edge", ge, we), ("kp_flat", gf, wf)):
        emit_grid(h, name, g)
        h.array(f"{name}_w", "int32_t", w)
    cases = golden_cases()
    plan = [(name, "kp_std", gs, ws) for name in cases]
    plan += [("edges_sat", "kp_edge", ge, we), ("random_sat", "kp_edge", ge, we),
             ("random_flat", "kp_flat", gf, wf)]
    sig = dict(cases, edges_sat=cases["edges"], random_sat=cases["random"], random_flat=cases["random"])
    for name, _, g, w in plan:
        y, psi = kp_process_q(sig[name], g, w)
        h.define(f"KP_CASE_{name.upper()}_N", len(y))
        h.array(f"kp_case_{name}_u", "int16_t", sig[name])
        h.array(f"kp_case_{name}_y", "int16_t", y)
        if name == "realistic":
            h.array("kp_case_realistic_psi_end", "int16_t", psi[-1])
    h.comment("case table: name, grid, input, output, length")
    h.parts.append("#define KP_GOLDEN_CASES(X) \\\n" + " \\\n".join(
        f"    X({name}, {set_})" for name, set_, _, _ in plan))
    return str(h)


# --------------------------------------------------------------- float vs fixed

def error_bound_lsb(grid: fkp.KPGrid, g: KPGridQ, w, w_q24) -> float:
    """Worst-case |y_fixed - y_float| [q15 LSB] on the same (q15) input.

    Per operator the ridge differs by at most 0.5 * slope (threshold rounding)
    + 0.5 (slope rounding over |x| < 2^16) + 0.5 (ridge rounding) + the ridge
    height's rounding; max/min do not grow the difference. The output adds the
    density's rounding and the final rounding (0.5 LSB).
    """
    w = np.asarray(w, dtype=np.float64)
    e_top = abs(g.rmax - grid.nmax * Q15.one)
    e_psi = 0.5 * grid.slope + 0.5 + 0.5 + e_top
    e_w = np.abs(np.asarray(w_q24) / Q24.one - w)
    return float(np.sum(np.abs(w)) * e_psi + np.sum(e_w) * Q15.one + 0.5)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, y_float, y_fixed_q15) for the KP model on a realistic signal."""
    grid, g, w, wq = std_grid()
    out = []
    for name, u in (("realistic sweep 2 s", realistic_signal(20000, seed=11)),
                    ("full-scale steps", _steps(4000))):
        yf = fkp.kp_model(u / Q15.one, grid, w)
        yq, _ = kp_process_q(u, g, wq)
        out.append((name, yf, yq))
    return out
