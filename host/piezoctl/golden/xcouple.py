"""Bit-exact golden model of ``firmware/core/xcouple.c`` (cross-coupling predictor).

:class:`XCoef` holds the kernel's coefficients, as floats (the reference,
:func:`process_float`) or as integers in their Q formats (:func:`quantize`,
:func:`process_q`, which computes exactly what the C kernel computes; see
``xcouple.h`` for the model, formats and bounds). :func:`from_hammerstein`
turns a host ``hammerstein`` model (physical units: the other axis' drive [V],
a position [um], coupling [um]) into the kernel's form on the controller's
q15 scales, with the output converted to this axis' drive units.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q16, Q24, QOverflowError
from ..ident.laguerre import laguerre_ab
from .export import CHeader

__all__ = ["XCoef", "MAX_M", "MAX_CH", "MAX_POW", "MAX_DEG", "MAX_SHIFT", "check", "quantize",
           "process_q", "process_float", "from_hammerstein", "laguerre_coef", "golden_cases",
           "c_header", "error_report"]

MAX_M, MAX_CH, MAX_POW, MAX_DEG, MAX_SHIFT = 4, 2, 8, 4, 10
ONE = 1 << 24


@dataclass(frozen=True)
class XCoef:
    """``struct piezo_xc_coef``; floats (FS units) or ints (q15 / q16 / q24)."""

    m: int
    n_ch: int
    n_pow: int
    n_deg: int
    u_center: float          # q15 (FS)
    u_gain: float            # q16
    x_center: float          # q15 (FS)
    x_gain: float            # q16
    a: np.ndarray            # (m, m) q24
    b: np.ndarray            # (m,) q24
    e: np.ndarray            # (m,) q24
    eta: np.ndarray          # (n_ch, n_pow, n_deg) q24
    xi: np.ndarray           # (n_ch, m, n_deg) q24


def laguerre_coef(m: int, q: float = 0.1, T: float = 2.0):
    """(A, B, E = (I - A)^-1 B) of ``m`` Laguerre filters (floats)."""
    a, b = laguerre_ab(m, q, T)
    e = np.linalg.solve(np.eye(m) - a, b)
    return a, b, e


def _state_shifts(k: XCoef) -> list[int]:
    """The init's state bounds: shift s_i per row (raises if none <= MAX_SHIFT)."""
    z = []
    for i in range(k.m):
        aii = int(k.a[i, i])
        rhs = abs(int(k.b[i])) * ONE + ONE + sum(abs(int(k.a[i, j])) * z[j] for j in range(i))
        for s in range(MAX_SHIFT + 1):
            zz = ONE << s
            if (ONE - aii) * zz >= rhs and abs(int(k.e[i])) < zz:
                z.append(zz)
                break
        else:
            raise QOverflowError(f"xcouple: no state bound 2^(24+s), s <= {MAX_SHIFT}, for filter {i}")
    return [int(np.log2(v)) - 24 for v in z]


def check(k: XCoef) -> None:
    """What ``piezo_xc_init`` checks; raises ValueError / QOverflowError like its refusals."""
    if not (1 <= k.m <= MAX_M and 1 <= k.n_ch <= MAX_CH and 1 <= k.n_pow <= MAX_POW and 1 <= k.n_deg <= MAX_DEG):
        raise ValueError(f"xcouple: sizes m={k.m} n_ch={k.n_ch} n_pow={k.n_pow} n_deg={k.n_deg} out of range")
    if k.u_gain <= 0 or k.x_gain <= 0 or not (-32768 <= k.u_center <= 32768 and -32768 <= k.x_center <= 32768):
        raise QOverflowError("xcouple: normalization out of range")
    a = np.asarray(k.a, dtype=np.int64)
    if np.any(np.triu(a, 1) != 0) or np.any(np.diag(a) < 0) or np.any(np.diag(a) >= ONE) \
            or np.any(np.abs(a) >= 2 * ONE) or np.any(np.abs(k.b) >= 2 * ONE):
        raise QOverflowError("xcouple: Laguerre A, B, E out of range")
    for c in range(k.n_ch):
        if int(np.abs(np.asarray(k.eta[c], dtype=np.int64)).sum()) > ONE:
            raise QOverflowError(f"xcouple: sum |eta| of channel {c} exceeds 1")
    shifts = _state_shifts(k)
    xi = np.abs(np.asarray(k.xi, dtype=np.int64))
    for c in range(k.n_ch):
        for i in range(k.m):
            if int(xi[c, i].sum()) + 1 > 1 << (35 - shifts[i]):
                raise QOverflowError(f"xcouple: sum |xi| of channel {c}, filter {i} exceeds 2^{35 - shifts[i]} "
                                     "(output accumulator bound)")


def quantize(k: XCoef) -> XCoef:
    """Float coefficients to the kernel's integers (rounding rule), checked like init."""
    q = XCoef(k.m, k.n_ch, k.n_pow, k.n_deg,
              int(np.floor(k.u_center + 0.5)), fixed.to_q(k.u_gain, Q16), int(np.floor(k.x_center + 0.5)),
              fixed.to_q(k.x_gain, Q16),
              fixed.to_q(np.asarray(k.a, float), Q24), fixed.to_q(np.asarray(k.b, float), Q24),
              fixed.to_q(np.asarray(k.e, float), Q24), fixed.to_q(np.asarray(k.eta, float), Q24),
              fixed.to_q(np.asarray(k.xi, float), Q24))
    check(q)
    return q



def _norm(v, c, g):
    n = fixed.rshift_rnd((int(v) - int(c)) * int(g), 16)
    return max(-32767, min(32767, n))


def _powers(v, n):
    out = [32768]
    for _ in range(1, n):
        out.append(fixed.rshift_rnd(out[-1] * v, 15))
    return out


def process_q(k: XCoef, u_q15, x_q15) -> np.ndarray:
    """The kernel from reset over the sequences u, x (q15): outputs q15 (int64 array)."""
    u_q15 = np.asarray(u_q15, dtype=np.int64).ravel()
    x_q15 = np.broadcast_to(np.asarray(x_q15, dtype=np.int64), u_q15.shape).ravel()
    m, nc, npw, nd = k.m, k.n_ch, k.n_pow, k.n_deg
    a = [[int(v) for v in row] for row in np.asarray(k.a)]
    b = [int(v) for v in k.b]
    e = [int(v) for v in k.e]
    eta = [[[int(v) for v in r] for r in ch] for ch in np.asarray(k.eta)]
    xi = [[[int(v) for v in r] for r in ch] for ch in np.asarray(k.xi)]
    z = [[0] * m for _ in range(nc)]
    started = False
    out = np.empty(u_q15.size, dtype=np.int64)
    for t in range(u_q15.size):
        p = _powers(_norm(u_q15[t], k.u_center, k.u_gain), npw)
        sx = _powers(_norm(x_q15[t], k.x_center, k.x_gain), nd)
        f = [[fixed.rshift_rnd(p[j] * sx[bb], 15) for bb in range(nd)] for j in range(npw)]
        mu = []
        for c in range(nc):
            acc = 0
            for j in range(npw):
                for bb in range(nd):
                    acc += eta[c][j][bb] * f[j][bb]
            mu.append(fixed.rshift_rnd(acc, 15))
        if not started:
            for c in range(nc):
                z[c] = [fixed.rshift_rnd(e[i] * mu[c], 24) for i in range(m)]
            started = True
        acc_out = 0
        for c in range(nc):
            for i in range(m):
                rho = sum(xi[c][i][bb] * sx[bb] for bb in range(nd))
                acc_out += fixed.rshift_rnd(rho, 15) * z[c][i]
            z[c] = [fixed.rshift_rnd(b[i] * mu[c] + sum(a[i][j] * z[c][j] for j in range(i + 1)), 24)
                    for i in range(m)]
        out[t] = fixed.sat_q15(fixed.rshift_rnd(acc_out, 33))
    return out


def process_float(k: XCoef, u_fs, x_fs) -> np.ndarray:
    """The float reference on full-scale inputs (q15 / 32768); output in FS.

    Same model as :func:`process_q` without rounding (the normalized inputs
    are clamped to +-32767/32768 like the kernel's).
    """
    u_fs = np.asarray(u_fs, dtype=float).ravel()
    x_fs = np.broadcast_to(np.asarray(x_fs, dtype=float), u_fs.shape).ravel()
    lim = 32767 / 32768
    un = np.clip((u_fs - k.u_center / 32768.0) * k.u_gain, -lim, lim)
    xn = np.clip((x_fs - k.x_center / 32768.0) * k.x_gain, -lim, lim)
    p = un[:, None] ** np.arange(k.n_pow)[None, :]
    sx = xn[:, None] ** np.arange(k.n_deg)[None, :]
    a, b, e = np.asarray(k.a, float), np.asarray(k.b, float), np.asarray(k.e, float)
    eta, xi = np.asarray(k.eta, float), np.asarray(k.xi, float)
    mu = np.einsum("tj,tb,cjb->tc", p, sx, eta)
    rho = np.einsum("tb,cib->tci", sx, xi)
    z = e[None, :] * mu[0][:, None]  # (c, i)
    y = np.empty(u_fs.size)
    for t in range(u_fs.size):
        y[t] = float(np.sum(rho[t] * z))
        z = z @ a.T + mu[t][:, None] * b[None, :]
    return y


def from_hammerstein(params: dict, drive_scale, position_scale, drive_per_um: float) -> XCoef:
    """The kernel's float coefficients for a host ``hammerstein`` model.

    Parameters
    ----------
    params : dict
        From :func:`piezoctl.ident.hammerstein.fit` with ``harmonics == 0``,
        powers within 0..7, degree <= 3, m <= 4, at most 2 channels.
    drive_scale : Scale
        The scale of the other axis' drive (its q15 <-> V).
    position_scale : Scale
        The scale of the position input x (q15 <-> um), ``p_mid``, ``p_half``.
    drive_per_um : float
        This axis' drive per micrometre of displacement [FS of drive per um]:
        the output is the predicted coupling converted to this axis' drive.

    The channels are rescaled so that sum |eta_c| = 1 - 2^-18 (the kernel's
    bound on mu is 1, with room for the rounding) with the gain moved into xi.
    """
    if int(params.get("harmonics", 0)) != 0:
        raise ValueError("xcouple: the firmware kernel has no trigonometric input functions (harmonics must be 0)")
    powers = [int(k) for k in params["powers"]]
    n_pow = max(powers) + 1
    m, n_deg = int(params["m"]), int(params["degree"]) + 1
    chans = params["channels_fit"]
    if n_pow > MAX_POW or n_deg > MAX_DEG or m > MAX_M or len(chans) > MAX_CH:
        raise ValueError(f"xcouple: model too large for the kernel (m={m}, degree={n_deg - 1}, "
                         f"max power {n_pow - 1}, channels {len(chans)})")
    a, b, e = laguerre_coef(m, float(params["q"]), float(params["T"]))
    # u_n = (u_V - u_c)/u_s = (u_fs - (u_c - d_mid)/d_half) * d_half/u_s
    d_mid = 0.5 * (drive_scale.drive_min_v + drive_scale.drive_max_v)
    d_half = 0.5 * (drive_scale.drive_max_v - drive_scale.drive_min_v)
    u_center = (params["u_center"] - d_mid) / d_half * 32768.0
    u_gain = d_half / params["u_scale"]
    x_center = (params["x_center"] - position_scale.p_mid) / position_scale.p_half * 32768.0
    x_gain = position_scale.p_half / params["x_scale"]
    eta = np.zeros((len(chans), n_pow, n_deg))
    xi = np.zeros((len(chans), m, n_deg))
    for c, ch in enumerate(chans):
        ec = np.asarray(ch["eta"], float)   # (len(powers), d + 1)
        for row, k in enumerate(powers):
            eta[c, k] += ec[row]
        # sum |eta_c| = 1 - 2^-18: the q24 rounding of up to 32 terms stays within 1
        s = float(np.abs(eta[c]).sum()) / (1.0 - 2.0 ** -18)
        if s == 0.0:
            continue
        eta[c] /= s
        xi[c] = np.asarray(ch["xi"], float) * s * drive_per_um
    return XCoef(m, len(chans), n_pow, n_deg, u_center, u_gain, x_center, x_gain, a, b, e, eta, xi)


# ---------------------------------------------------------------- golden vectors
def _demo(rng, m, nc, npw, nd, eta_sum=0.9, xi_sum=0.05, **kw) -> XCoef:
    a, b, e = laguerre_coef(m)
    eta = rng.standard_normal((nc, npw, nd))
    xi = rng.standard_normal((nc, m, nd))
    for c in range(nc):
        eta[c] *= eta_sum / np.abs(eta[c]).sum()
    xi *= xi_sum / np.abs(xi).sum()
    base = dict(u_center=kw.get("u_center", 0.0), u_gain=kw.get("u_gain", 1.0),
                x_center=kw.get("x_center", 0.0), x_gain=kw.get("x_gain", 1.0))
    return XCoef(m, nc, npw, nd, a=a, b=b, e=e, eta=eta, xi=xi, **base)


def _edge_sums(k: XCoef) -> XCoef:
    """Integers with sum |eta_c| = 2^24 and every sum_b |xi_cib| + 1 = 2^(35 - s_i) (the bounds, met)."""
    eta = np.asarray(k.eta).copy()
    for c in range(k.n_ch):
        eta[c, 0, 0] += ONE - int(np.abs(eta[c]).sum()) if eta[c, 0, 0] >= 0 else -(ONE - int(np.abs(eta[c]).sum()))
    shifts = _state_shifts(k)
    xi = np.zeros_like(np.asarray(k.xi))
    for c in range(k.n_ch):
        for i in range(k.m):
            total = (1 << (35 - shifts[i])) - 1
            part = total // k.n_deg
            vals = [part] * k.n_deg
            vals[0] += total - part * k.n_deg
            sign = 1 if (c + i) % 2 == 0 else -1
            xi[c, i] = [sign * v * (1 if b % 2 == 0 else -1) for b, v in enumerate(vals)]
    out = dataclasses.replace(k, eta=eta, xi=xi)
    check(out)
    return out


def _signals(T: int, rng, kind: str):
    t = np.arange(T)
    if kind == "sine":
        u = 0.8 * np.sin(2 * np.pi * t / 400.0) + 0.1 * np.sin(2 * np.pi * t / 37.0)
        x = 0.6 * np.sin(2 * np.pi * t / 1500.0) - 0.1
    elif kind == "steps":
        u = np.repeat(rng.uniform(-1, 1, T // 50 + 1), 50)[:T]
        x = np.repeat(rng.uniform(-1, 1, T // 170 + 1), 170)[:T]
    else:  # full scale: the rails and random samples
        u = rng.choice([-1.0, 32767 / 32768, 0.0], T)
        u[::7] = rng.uniform(-1, 1, u[::7].size)
        x = rng.choice([-1.0, 32767 / 32768], T)
    uq = fixed.to_q(np.clip(u, -1, 32767 / 32768), Q15)
    xq = fixed.to_q(np.clip(x, -1, 32767 / 32768), Q15)
    return uq, xq


def golden_cases(T: int = 1500) -> dict[str, tuple[XCoef, np.ndarray, np.ndarray, np.ndarray]]:
    """name -> (integer coefficients, u, x, expected y)."""
    rng = np.random.default_rng(20261122)
    cases = {}
    std = quantize(_demo(rng, 2, 2, 4, 3, u_center=-3000.0, u_gain=1.1, x_center=2000.0, x_gain=1.3))
    cases["std"] = (std, *_signals(T, rng, "sine"))
    big = _edge_sums(quantize(_demo(rng, 4, 2, 8, 4, xi_sum=0.9)))
    cases["max"] = (big, *_signals(T, rng, "full"))
    mid = quantize(_demo(rng, 4, 2, 8, 4, xi_sum=0.05, u_center=1234.0, u_gain=0.9))
    cases["steps"] = (mid, *_signals(T, rng, "steps"))
    one = quantize(_demo(rng, 1, 1, 2, 1, eta_sum=1.0, xi_sum=0.1))
    cases["single"] = (one, *_signals(T // 3, rng, "steps"))
    # normalization clamps: a gain that maps most inputs beyond +-1
    clamp = quantize(_demo(rng, 3, 1, 5, 2, u_center=5000.0, u_gain=6.0, x_center=-20000.0, x_gain=9.0))
    cases["clamp"] = (clamp, *_signals(T // 2, rng, "sine"))
    # output saturation: E = B / (1 - A) = 1.5, xi = 1: |y| reaches 1.5 FS
    sat = quantize(XCoef(1, 1, 2, 1, 0.0, 1.0, 0.0, 1.0, np.array([[0.5]]), np.array([0.75]),
                         np.array([1.5]), np.array([[[0.0], [1.0]]]), np.array([[[1.0]]])))
    cases["sat"] = (sat, *_signals(T // 3, rng, "steps"))
    return {name: (k, u, x, process_q(k, u, x)) for name, (k, u, x) in cases.items()}


def c_header() -> str:
    h = CHeader("xcouple")
    h.comment("golden vectors of piezo_xc_process: coefficients, inputs u and x, expected y (q15)")
    names = []
    for name, (k, u, x, y) in golden_cases().items():
        names.append(name)
        p = f"xc_{name}"
        for key, v in (("M", k.m), ("NCH", k.n_ch), ("NPOW", k.n_pow), ("NDEG", k.n_deg),
                       ("UC", k.u_center), ("UG", k.u_gain), ("XC", k.x_center), ("XG", k.x_gain)):
            h.define(f"{p}_{key}", v)
        h.array(f"{p}_a", "int32_t", np.asarray(k.a).ravel())
        h.array(f"{p}_b", "int32_t", k.b)
        h.array(f"{p}_e", "int32_t", k.e)
        h.array(f"{p}_eta", "int32_t", np.asarray(k.eta).ravel())
        h.array(f"{p}_xi", "int32_t", np.asarray(k.xi).ravel())
        h.array(f"{p}_u", "int16_t", u)
        h.array(f"{p}_x", "int16_t", x)
        h.array(f"{p}_y", "int16_t", y)
    h.parts.append("#define XC_GOLDEN_CASES(X) " + " ".join(f"X({n})" for n in names))
    return str(h)


def error_report(T: int = 20000) -> dict:
    """Float vs fixed on a realistic coupling predictor: max error [q15 LSB] and SNR [dB]."""
    rng = np.random.default_rng(5)
    k = _demo(rng, 2, 2, 4, 3, xi_sum=0.02, u_center=-1000.0, u_gain=1.05, x_gain=1.2)
    kq = quantize(k)
    t = np.arange(T)
    u = fixed.to_q(0.85 * np.sin(2 * np.pi * t / 1000.0) + 0.1 * np.sin(2 * np.pi * t / 91.0), Q15)
    x = fixed.to_q(0.7 * np.sin(2 * np.pi * t / 7000.0), Q15)
    yq = process_q(kq, u, x).astype(float)
    yf = process_float(k, u / 32768.0, x / 32768.0) * 32768.0
    err = yq - yf
    return {"max_lsb": float(np.max(np.abs(err))), "snr_db": float(10 * np.log10(np.mean(yf ** 2) / np.mean(err ** 2))),
            "peak_lsb": float(np.max(np.abs(yf)))}
