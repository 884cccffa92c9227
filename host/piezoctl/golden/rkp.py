"""Bit-exact golden model of ``firmware/core/rkp.c`` (rate-dependent KP model).

See ``rkp.h`` and ``docs/kernels-kp.md``. :func:`quantize` turns the float
reference's parameters (``piezoctl.models.kp.rkp_model``) into the kernel's
coefficients and raises :class:`piezoctl.fixed.QOverflowError` when one does
not fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed, interface
from ..fixed import Q15, Q16, Q24, QOverflowError
from ..models import kp as fkp
from . import kp as gkp
from .export import CHeader

__all__ = [
    "RKPQ", "MAX_RBF", "MAX_CENTER_Q24", "STEP_SHIFT", "check", "quantize", "gauss_q",
    "rate_q", "features_q", "rkp_process_q", "std_model", "c_header", "error_report",
]

MAX_RBF = 32                 # PIEZO_RKP_MAX_RBF
MAX_CENTER_Q24 = 1 << 26     # PIEZO_RKP_MAX_CENTER_Q24
STEP_SHIFT = 10              # LUT step zmax / (n - 1) = 2^-6 is 2^10 in q16
ZMAX_Q16 = fixed.to_q(interface.GAUSS_ZMAX, Q16)
LUT = np.asarray(interface.GAUSS_LUT_Q15, dtype=np.int64)
assert (interface.GAUSS_LUT_N - 1) << STEP_SHIFT == ZMAX_Q16


@dataclass(frozen=True)
class RKPQ:
    """The C ``struct piezo_rkp_coeffs`` in integers."""

    grid: gkp.KPGridQ
    theta: np.ndarray      # int64 (M, N): theta[m, j] = Theta_jm, q24
    center: np.ndarray     # int64 (M,), q24 FS per sample
    inv_width: np.ndarray  # int64 (M,), q16 samples per FS
    alpha: int             # q16, 1..65536

    @property
    def M(self) -> int:
        return int(self.center.size)


def check(r: RKPQ) -> None:
    """Raise where ``piezo_rkp_init`` would refuse the coefficients."""
    gkp.check_grid(r.grid)
    if not 1 <= r.M <= MAX_RBF:
        raise ValueError(f"number of Gaussians must be in 1..{MAX_RBF}, got {r.M}")
    if r.theta.shape != (r.M, r.grid.N) or r.inv_width.shape != (r.M,):
        raise ValueError("theta must be (M, N) and inv_width (M,)")
    if not 1 <= r.alpha <= Q16.one:
        raise ValueError(f"alpha_q16 must be in 1..65536, got {r.alpha}")
    if np.any(np.abs(r.center) > MAX_CENTER_Q24):
        raise QOverflowError("a rate center exceeds 4 FS per sample")
    if np.any(r.inv_width < 1) or np.any(r.inv_width > Q16.max):
        raise QOverflowError("inverse width outside 1..INT32_MAX q16")
    if np.any(r.theta < Q24.min) or np.any(r.theta > Q24.max):
        raise QOverflowError("theta outside q24")
    if np.any(np.sum(np.abs(r.theta), axis=0) > Q24.max):
        raise QOverflowError("sum_m |Theta_jm| exceeds INT32_MAX q24 for an operator")


def quantize(grid: fkp.KPGrid, theta, dt: float, centers, widths, filt: float) -> RKPQ:
    """Kernel coefficients from the float model's parameters.

    Parameters
    ----------
    grid : KPGrid
    theta : array_like, shape (N, M)
        Density coefficients.
    dt : float
        Sample period [s].
    centers, widths : array_like, shape (M,)
        Gaussian centers and standard deviations [FS/s]; the kernel works per
        sample: ``center_q24 = q24(c dt)``, ``inv_width_q16 = q16(1 / (sigma dt))``.
    filt : float
        Rate filter coefficient ``a`` in (0, 1]: ``alpha_q16 = q16(a)``.
    """
    theta = np.asarray(theta, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64).ravel()
    sg = np.asarray(widths, dtype=np.float64).ravel()
    if np.any(sg <= 0):
        raise ValueError("widths must be > 0")
    r = RKPQ(grid=gkp.quantize_grid(grid), theta=fixed.to_q(theta.T, Q24),
             center=fixed.to_q(c * dt, Q24), inv_width=fixed.to_q(1.0 / (sg * dt), Q16),
             alpha=fixed.to_q(filt, Q16))
    check(r)
    return r


def gauss_q(z_q16) -> np.ndarray:
    """``piezo_rkp_gauss_q15`` for ``z_q16 >= 0``."""
    z = np.asarray(z_q16, dtype=np.int64)
    inside = z < ZMAX_Q16
    zc = np.where(inside, z, 0)
    i = zc >> STEP_SHIFT
    f = zc & ((1 << STEP_SHIFT) - 1)
    a = LUT[i]
    b = LUT[i + 1]
    return np.where(inside, a + fixed.rshift_rnd((b - a) * f, STEP_SHIFT), 0).astype(np.int64)


def rate_q(u_q15, alpha: int, u_prev: int, rate0: int = 0) -> np.ndarray:
    """Filtered rate ``rate_q24`` after each sample (the kernel's step 1)."""
    out = np.empty(len(u_q15), dtype=np.int64)
    q, up = int(rate0), int(u_prev)
    for k, u in enumerate(np.asarray(u_q15, dtype=np.int64).tolist()):
        d = (u - up) * 512
        q += fixed.rshift_rnd((d - q) * alpha, 16)
        out[k] = q
        up = u
    return out


def features_q(rate_q24, r: RKPQ) -> np.ndarray:
    """Features ``F`` (T, M) in q15 from the filtered rate (step 2)."""
    dz = np.abs(np.asarray(rate_q24, dtype=np.int64)[:, None] - r.center[None, :])
    z = fixed.rshift_rnd(dz * r.inv_width[None, :], 24)
    return gauss_q(np.minimum(z, ZMAX_Q16))


def rkp_process_q(u_q15, r: RKPQ):
    """``piezo_rkp_process`` over a signal from reset: returns ``(y_q15, psi, w, rate)``.

    ``psi`` and ``w`` are (T, N) trajectories, ``rate`` (T,).
    """
    u = np.asarray(u_q15, dtype=np.int64).ravel()
    rate = rate_q(u, r.alpha, r.grid.nmin)
    F = features_q(rate, r)
    w = fixed.rshift_rnd(F @ r.theta, 15)            # (T, N), exact in int64
    psi = gkp.kp_outputs_q(u, r.grid)
    acc = np.sum(psi * w, axis=1)
    return fixed.sat_q15(fixed.rshift_rnd(acc, 24)), psi, w, rate


# ------------------------------------------------------------------ vectors

DT = 1e-4  # 10 kHz tick


def std_model():
    """Reference RKP: L = 10, 13 Gaussians over +-600 FS/s, 500 Hz rate filter.

    The density leans with the rate (more weight on wide loops when fast), as a
    piezo's loops widen with frequency. Returns ``(grid, theta, centers, widths, filt)``.
    """
    grid = fkp.kp_grid(10)
    w0 = gkp.demo_density(grid)
    centers = np.linspace(-600.0, 600.0, 13)
    widths = np.full(13, 100.0)
    # sum_m exp(-((x - c_m)/sigma)^2/2) ~ sqrt(2 pi) for centers one sigma apart
    lean = 1.0 + 0.4 * np.tanh(np.abs(centers)[None, :] / 300.0) * ((grid.n2 - grid.n1)[:, None] - 0.5)
    theta = w0[:, None] * lean / np.sqrt(2.0 * np.pi)
    return grid, theta, centers, widths, fkp.lowpass_coefficient(500.0, DT)


def edge_model() -> RKPQ:
    """Extreme coefficients: centers at +-4 FS/sample and 0, the largest inverse
    width, theta rows summing to exactly INT32_MAX, no rate filtering."""
    g, _ = gkp.edge_grid()
    M = 5
    center = np.array([-MAX_CENTER_Q24, -(1 << 20), 0, 1 << 20, MAX_CENTER_Q24], dtype=np.int64)
    inv_width = np.array([65536, 3000, Q16.max, 1 << 18, 1 << 15], dtype=np.int64)
    theta = np.zeros((M, g.N), dtype=np.int64)
    theta[2, :] = np.where(np.arange(g.N) % 2 == 0, 1 << 28, -(1 << 28))
    theta[3, :] = 1 << 27
    theta[4, :] = -(1 << 26)
    rest = Q24.max - (1 << 28) - (1 << 27) - (1 << 26)
    theta[0, :] = rest // 2
    theta[1, :] = -(rest - rest // 2)               # sum_m |Theta_jm| = INT32_MAX exactly
    theta *= np.array([1, -1, 1, 1, -1, 1, -1, -1, 1, -1], dtype=np.int64)[None, :]
    r = RKPQ(grid=g, theta=theta, center=center, inv_width=inv_width, alpha=Q16.one)
    check(r)
    assert int(np.max(np.sum(np.abs(theta), axis=0))) == Q24.max
    return r


def slow_model() -> RKPQ:
    """The slowest rate filter (alpha = 1 LSB) on the reference plane."""
    grid, theta, centers, widths, _ = std_model()
    r = quantize(grid, theta, DT, centers, widths, 1.0)
    r = RKPQ(grid=r.grid, theta=r.theta, center=r.center, inv_width=r.inv_width, alpha=1)
    check(r)
    return r


def _emit(h: CHeader, prefix: str, r: RKPQ) -> None:
    gkp.emit_grid(h, prefix, r.grid)
    h.define(f"{prefix}_NRBF", r.M)
    h.define(f"{prefix}_ALPHA", r.alpha)
    h.array(f"{prefix}_theta", "int32_t", r.theta.ravel())
    h.array(f"{prefix}_center", "int32_t", r.center)
    h.array(f"{prefix}_inv_width", "int32_t", r.inv_width)


def c_header() -> str:
    h = CHeader("rkp")
    h.comment("RKP golden vectors: coefficients, inputs, outputs (q15), end states.")
    grid, theta, centers, widths, filt = std_model()
    std = quantize(grid, theta, DT, centers, widths, filt)
    edge = edge_model()
    slow = slow_model()
    for name, r in (("rkp_std", std), ("rkp_edge", edge), ("rkp_slow", slow)):
        _emit(h, name, r)
    # Gaussian LUT interpolation over its whole range, ties and the end.
    rng = np.random.default_rng(4)
    z = np.concatenate([np.arange(0, 4096, 97), np.arange(0, ZMAX_Q16 + 1, 1024),
                        [ZMAX_Q16 - 1, ZMAX_Q16, ZMAX_Q16 + 1, 512, 1536, (1 << 31) - 1],
                        rng.integers(0, ZMAX_Q16 + 5000, 400)]).astype(np.int64)
    h.define("RKP_GAUSS_N", z.size)
    h.array("rkp_gauss_z_q16", "int32_t", z)
    h.array("rkp_gauss_f_q15", "int16_t", gauss_q(z))

    cases = gkp.golden_cases()
    plan = [(name, "rkp_std", std, cases[name]) for name in cases]
    plan += [("edges_edge", "rkp_edge", edge, cases["edges"]),
             ("random_edge", "rkp_edge", edge, cases["random"]),
             ("alternating_edge", "rkp_edge", edge, cases["alternating"]),
             ("realistic_slow", "rkp_slow", slow, cases["realistic"])]
    for name, _, r, u in plan:
        y, psi, w, rate = rkp_process_q(u, r)
        h.array(f"rkp_case_{name}_u", "int16_t", u)
        h.array(f"rkp_case_{name}_y", "int16_t", y)
        if name == "realistic":
            h.array("rkp_case_realistic_psi_end", "int16_t", psi[-1])
            h.array("rkp_case_realistic_w_end", "int32_t", w[-1])
            h.define("RKP_CASE_REALISTIC_RATE_END", int(rate[-1]))
    h.parts.append("#define RKP_GOLDEN_CASES(X) \\\n" + " \\\n".join(
        f"    X({name}, {set_})" for name, set_, _, _ in plan))
    return str(h)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, y_float, y_fixed_q15) for the RKP model on realistic signals."""
    grid, theta, centers, widths, filt = std_model()
    r = quantize(grid, theta, DT, centers, widths, filt)
    out = []
    for name, u in (("realistic sweep 2 s", gkp.realistic_signal(20000, seed=11)),):
        yf = fkp.rkp_model(u / Q15.one, grid, theta, DT, centers, widths, filt)
        yq = rkp_process_q(u, r)[0]
        out.append((name, yf, yq))
    return out
