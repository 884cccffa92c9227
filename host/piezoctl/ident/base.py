"""The base model: a discretized Preisach plane followed by linear dynamics, sized by cross-validation.

One implementation serves ``piezoctl diagnose`` (its base model) and
``piezoctl identify --model refined`` (the same fit as a model kind).

Structure (model kind ``refined`` without terms, hysteresis type ``plane``)::

    v = (u - u_mid) / u_half             normalized over the settled calibration range
    H(v) = sum_j F_j(P_rj(v)) + offset   plays P of thresholds r_j = j / R, j = 0..R-1
    y = G[H(v) - offset] + offset        G discrete, unit static gain

Each ``F_j`` is piecewise linear on knots spread over the range its play's
output covered during calibration (``K`` knots across the full range for
``r = 0``, proportionally fewer for wider plays: the Preisach triangle), and
continues as a straight line beyond it. The model is linear in the knot values
once the plays are known, so every fit is a penalized least-squares problem.

Every ``F_j`` is **monotone** in the direction the output follows the drive
(non-decreasing when y rises with u): with a relay ``s - r .. s + r`` up exactly
when ``P_r(v) > s``, ``F_j' = 2 mu(s, r_j)``, so this is a Preisach density of
one sign, which Preisach, Maxwell-slip, KP and PI laws with positive weights all
have. It is solved as a non-negative least squares on the knot increments
(:func:`_plane_solve`). Without it a plane sized on a periodic calibration could
invent minor loops that run backwards (the micromanipulator's 1 Hz sine with 16
plays: test run NRMSE 0.46 unconstrained, 0.032 monotone; with the size rule
below both choose one play, 0.0235).

Fit (``fit_base``):

1. **Size by cross-validation.** On the *quasi-static* calibration samples
   (the drive differs from its zero-phase 20 Hz low-pass by at most 0.5 % of
   the range, and has for 20 ms), 32 interleaved time blocks per recording in
   two folds, the
   plane's size ``(R, K)`` and the weight of a roughness penalty (squared
   second differences of each play's function) are chosen from ``PLANE_PLAYS`` x
   ``PLANE_KNOTS`` x ``RIDGES`` (and with or without one Bouc-Wen column, its
   shape searched on the reversible curve alone) by the held-out RMS error (the
   smallest size within 2 % of the best). Only play counts R the calibration
   can resolve are offered: at least 2 R distinct reversal levels
   (:func:`reversal_levels`); a periodic calibration (two levels) gets R = 1,
   the reversible curve with the Bouc-Wen column. No parametric family: the grid of a Preisach
   density, not a law, is what is chosen.
2. **Dynamics** from everything the calibration excites: ARX of order 0, 2, 4
   or 6 from H's output to y, refined for output error; a higher order is kept
   when it lowers the simulation error by 5 % and is *plausible* (``|G| <= 3``
   above twice the calibration's band, the frequency below which 99 % of the
   energy of H's increments lies: a slow calibration cannot identify fast
   dynamics). The band is reported (``base_info.dynamics_band_hz``): above it
   the dynamics were not identified.
3. **Joint refit**: the plane's knot values refitted on all settled samples
   with every column filtered by G; then G again.

Every hysteresis fit also carries, per calibration recording, Legendre
polynomials 1..3 of time (not part of the model): slow drift during the
calibration (a creep transient after power-up, thermal settling) would
otherwise bend the hysteresis.
"""

from __future__ import annotations

import collections
import hashlib

import numpy as np
from scipy import optimize
from scipy import signal as sig

from ..dsp import blas_threads, filt, flush_subnormal, turning_points
from ..models.hysteresis import hat_basis, play_states
from .common import IdentError

__all__ = ["fit_base", "history_holdout", "fit_dynamics", "band_cps", "plausible", "block_masks", "plane_columns", "PlaneLayout",
           "MAX_ROWS", "smoothness_penalty", "reversal_levels"]

MAX_ROWS = 150_000       # samples entering the joint least-squares problem (evenly strided)
CV_ROWS = 24_000         # samples entering each size's cross-validation
PLANE_PLAYS = (1, 4, 8, 16)  # R: play thresholds r_j = j / R [normalized drive], j = 0..R-1 (R = 1: no plays,
                             # only the reversible curve F_0(v), with the Bouc-Wen column a Duhem-type model)
PLANE_KNOTS = (6, 12, 24)  # K: knots across the full normalized range [-1, 1] (for r = 0)
RIDGES = (1e-6, 1e-4, 1e-2, 1e-1, 1.0)   # weights of the roughness penalty (relative to the data's Gram diagonal)
BW_BETAS = tuple(float(x) for x in np.geomspace(0.5, 40.0, 7))   # Bouc-Wen column shapes [1/normalized drive]
BW_GAMMA_RATIOS = (-0.6, -0.3, 0.0, 0.3, 0.6)                    # gamma / beta; Nelder-Mead refines
CV_BLOCKS = 32           # interleaved blocks per calibration recording in the size cross-validation
SIZE_TOLERANCE = 1.02    # the smallest size within 2 % of the best cross-validated error is chosen
ORDERS = (0, 2, 4, 6)
QS_LP_HZ = 20.0          # quasi-static: drive within QS_TOL of its zero-phase low-pass at this frequency
QS_TOL = 0.005           # of the calibrated drive span
QS_GUARD_S = 0.02        # [s] after the drive was last fast
QS_MIN_FRACTION = 0.5    # fewer quasi-static samples than this fraction of the settled ones: size on all of them
MIN_PLAY_SPAN = 0.02     # a play whose output moved less than this [normalized drive] is left out
TREND_ORDER = 3
HOLDOUT_SEGMENTS = 4     # a single calibration recording is held out in this many contiguous segments
G_OUT_MAX = 3.0          # largest |G| allowed above twice the calibration's band (where it has no evidence)


def block_masks(n: int, n_blocks: int) -> np.ndarray:
    """Block index (0..n_blocks-1) of each of n samples (contiguous, equal blocks)."""
    return np.minimum((np.arange(n) * n_blocks) // max(n, 1), n_blocks - 1)


class PlaneLayout:
    """The columns of a plane of size (R, K): thresholds and, per play, its knots.

    Parameters
    ----------
    n_plays : int
        R, the number of play thresholds ``r_j = j / R``.
    n_knots : int
        K, knots across the full normalized range for ``r = 0``.
    spans : list of (float, float)
        Per threshold of the largest layout, the range [normalized drive] its play's output covered.
    r_all : ndarray
        The thresholds ``spans`` refers to.
    """

    def __init__(self, n_plays: int, n_knots: int, spans, r_all, bw=None):
        self.n_plays, self.n_knots = n_plays, n_knots
        self.bw = bw     # (beta, gamma) of the optional Bouc-Wen column, or None
        self.r, self.knots, self.index = [], [], []
        for j in range(n_plays):
            r = j / n_plays
            i = int(np.argmin(np.abs(np.asarray(r_all) - r)))
            lo, hi = spans[i]
            if hi - lo < MIN_PLAY_SPAN:
                continue
            k = max(2, int(np.ceil(n_knots * (hi - lo) / 2.0)) + 1)
            self.r.append(r)
            self.index.append(i)
            self.knots.append(np.linspace(lo, hi, k))
        self.n_plane = sum(k.size - 1 for k in self.knots)   # the first hat of each play goes to the offset
        self.n_cols = self.n_plane + (1 if bw else 0)

    def values(self, theta) -> list:
        """Knot values per play from the column coefficients (first knot 0)."""
        out, c = [], 0
        for k in self.knots:
            out.append(np.concatenate([[0.0], theta[c:c + k.size - 1]]))
            c += k.size - 1
        return out


def _bw_state(v, bw, v_rest):
    from ..models.hysteresis import bouc_wen_h
    return bouc_wen_h(v, bw[0], bw[1], v_rest)


def plane_columns(P, layout: PlaneLayout, rows=None, v=None, v_rest=0.0) -> np.ndarray:
    """The plane's columns (n, layout.n_cols) from the play states ``P`` (T, n_all) at ``rows`` (default all);
    the Bouc-Wen column (when the layout has one) from the normalized drive ``v``."""
    cols = []
    for i, kn in zip(layout.index, layout.knots):
        x = P[:, i] if rows is None else P[rows, i]
        cols.append(hat_basis(x, kn)[:, 1:])
    if layout.bw:
        hb = _bw_state(v, layout.bw, v_rest)
        cols.append((hb if rows is None else hb[rows])[:, None])
    return np.hstack(cols) if cols else np.zeros((P.shape[0] if rows is None else len(rows), 0))


def smoothness_penalty(layout: PlaneLayout, n_extra: int) -> np.ndarray:
    """Penalty matrix (n, n) of the plane's roughness: per play, the squared second differences of its knot
    values (first value fixed at 0) divided by the knot spacing cubed (a discrete integral of F''^2), so a
    cell of the Preisach plane that the data did not visit is filled smoothly from its neighbours instead of
    being pulled to zero. ``n_extra`` unpenalized columns (trends, offset) follow the plane's."""
    n = layout.n_cols + n_extra      # the Bouc-Wen column (if any), trends and offset are not penalized
    Om = np.zeros((n, n))
    c = 0
    for kn in layout.knots:
        k = kn.size
        if k >= 3:
            h = float(kn[1] - kn[0])
            D = np.zeros((k - 2, k))
            for i in range(k - 2):
                D[i, i:i + 3] = (1.0, -2.0, 1.0)
            D = D[:, 1:] / h ** 1.5       # value 0 is fixed
            Om[c:c + k - 1, c:c + k - 1] += D.T @ D
        c += k - 1
    return Om


def _penalized(A, ridge, Om=None):
    """A + ridge * s * Om (Om scaled to unit mean diagonal; default the identity) + 1e-10 * s * I, s = mean(diag A):
    the penalized normal matrix of every plane fit."""
    s = float(np.mean(np.diag(A))) or 1.0
    M = A.copy()
    if Om is None:
        M[np.diag_indices_from(M)] += ridge * s
    else:
        M += ridge * s * Om / max(float(np.mean(np.diag(Om))), 1e-300)
    M[np.diag_indices_from(M)] += 1e-10 * s
    return M


def _ridge_solve(A, b, ridge, Om=None):
    """Solve (A + ridge * s * Om + 1e-10 * s * I) x = b, s = mean(diag A): a roughness penalty ``Om`` (default: the
    identity, plain ridge) scaled to the data."""
    M = _penalized(A, ridge, Om)
    try:
        return np.linalg.solve(M, b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(M, b, rcond=1e-12)[0]


def _cumulative(layout: PlaneLayout, n: int) -> np.ndarray:
    """L (n, n) with c = L d: each play's knot values (first fixed at 0) as cumulative sums of its increments
    ``d``; the other ``n - layout.n_plane`` columns (Bouc-Wen, trends, offset) unchanged."""
    L = np.eye(n)
    c = 0
    for kn in layout.knots:
        k = kn.size - 1
        L[c:c + k, c:c + k] = np.tril(np.ones((k, k)))
        c += k
    return L


def _plane_solve(A, b, ridge, Om, layout: PlaneLayout, sign: float):
    """The penalized least squares of :func:`_ridge_solve` with every play's function monotone in the direction
    ``sign`` (+1: non-decreasing; 0: unconstrained): a Preisach density of one sign. Positive-density laws
    (Preisach, Maxwell slip, KP, PI with positive weights) satisfy it; it keeps a plane sized on few reversal
    levels from inventing minor loops that run backwards.

    Solved on the increments d (c = L d): minimize 1/2 x' M x - q' x over x = (sign d, f), d the plane's
    increments (>= 0 after the sign), f the free columns (Bouc-Wen, trends, offset) eliminated by their Schur
    complement; the bounded part is a non-negative least squares on the Cholesky factor (Lawson-Hanson)."""
    if not sign or layout.n_plane == 0:
        return _ridge_solve(A, b, ridge, Om)
    from scipy.linalg import cho_factor, cho_solve, solve_triangular
    from scipy.optimize import nnls
    n, p = A.shape[0], layout.n_plane
    M = _penalized(A, ridge, Om)
    L = _cumulative(layout, n)
    L[:, :p] *= sign
    Md, qd = L.T @ M @ L, L.T @ b
    sc = np.sqrt(np.maximum(np.diag(Md), 1e-300))       # unit diagonal: a better conditioned factor
    Md, qd = Md / np.outer(sc, sc), qd / sc
    Md[np.diag_indices_from(Md)] += 1e-9
    try:
        if n > p:   # eliminate the free columns: x_f = M_ff^-1 (q_f - M_fd x_d)
            cf = cho_factor(Md[p:, p:])
            W = cho_solve(cf, Md[p:, :p])
            wq = cho_solve(cf, qd[p:])
            S, qs = Md[:p, :p] - Md[:p, p:] @ W, qd[:p] - Md[:p, p:] @ wq
        else:
            S, qs = Md, qd
        R = np.triu(cho_factor(S, lower=False)[0])
    except np.linalg.LinAlgError:
        return _ridge_solve(A, b, ridge, Om)
    xd, _ = nnls(R, solve_triangular(R, qs, trans="T", lower=False), maxiter=50 * p)
    x = np.concatenate([xd, wq - W @ xd]) if n > p else xd
    return L @ (x / sc)


def _trends(ns, k0s) -> list:
    """Per recording, block columns of slow trends (Legendre P1..P3 of the settled time span; zero in the other
    recordings' blocks): they absorb slow drift in the calibration and are not part of the model."""
    out = []
    m = TREND_ORDER
    for i, (n, k0) in enumerate(zip(ns, k0s)):
        T = np.zeros((n, m * len(ns)))
        x = np.linspace(-1.0, 1.0, max(n - k0, 2))
        x = np.concatenate([np.full(k0, -1.0), x])[:n]
        T[:, i * m:(i + 1) * m] = np.polynomial.legendre.legvander(x, m)[:, 1:]
        out.append(T)
    return out


def _quasi_static(v, dt, k0) -> np.ndarray:
    """Samples where the drive is slow: within QS_TOL (of the normalized span 2) of its zero-phase low-pass at
    QS_LP_HZ, and has been for QS_GUARD_S; settled samples only."""
    fs = 1.0 / dt
    if v.size < 32 or QS_LP_HZ >= 0.4 * fs:
        m = np.ones(v.size, bool)
    else:
        sos = sig.butter(2, QS_LP_HZ, fs=fs, output="sos")
        fast = np.abs(v - sig.sosfiltfilt(sos, v)) > 2.0 * QS_TOL
        g = max(1, int(round(QS_GUARD_S * fs)))
        c = np.cumsum(fast.astype(int))
        prev = np.concatenate([np.zeros(g, int), c[:-g]]) if c.size > g else np.zeros(c.size, int)
        m = (c - prev) == 0
    m[:k0] = False
    return m


def _strided(mask, rows) -> np.ndarray:
    idx = np.flatnonzero(mask)
    if idx.size > rows:
        idx = idx[:: int(np.ceil(idx.size / rows))]
    return idx


def band_cps(xs, k0s) -> float:
    """Normalized frequency [cycles/sample] below which 99 % of the energy of the inputs' increments lies."""
    f_all, p_all = [], []
    for x, k0 in zip(xs, k0s):
        dx = np.diff(np.asarray(x, float)[k0:])
        if dx.size < 16:
            continue
        p_all.append(np.abs(np.fft.rfft(dx)) ** 2)
        f_all.append(np.fft.rfftfreq(dx.size, 1.0))
    if not f_all:
        return 0.5
    f, p = np.concatenate(f_all), np.concatenate(p_all)
    o = np.argsort(f)
    c = np.cumsum(p[o])
    return float(f[o][min(np.searchsorted(c, 0.99 * c[-1]), f.size - 1)])


def plausible(m, band) -> bool:
    """A dynamics model the calibration supports: |G| at most ``G_OUT_MAX`` above twice the calibration's
    band ``band`` [cycles/sample]. A slow calibration cannot identify fast dynamics, and an ARX fitted on it
    can put large gains at high frequency (a 20 Hz calibration gave |G| = 27 at Nyquist), which a step then
    excites."""
    if m is None:
        return False
    b, a = m
    if len(a) == 1 and len(b) == 1:
        return True
    f0 = min(2.0 * band, 0.5)
    if f0 >= 0.5:
        return True
    w = np.linspace(2 * np.pi * f0, np.pi, 256)
    _, hw = sig.freqz(b, a, worN=w)
    return bool(np.max(np.abs(hw)) <= G_OUT_MAX)


ARX_COND_MAX = 1e12       # largest condition number of the scaled Gram matrix the refined normal equations take
ARX_REFINE_STEPS = 3      # refinement steps of the normal equations' solution (each gains a factor ~cond(G) eps, down to a floor of about cond(X) eps: the residual is computed in working precision)


def _lstsq_qr(X, y):
    """Least squares on unit-RMS columns by pivoted QR (LAPACK gelsy, rank cutoff 1e-10): the reference, and what a
    (nearly) rank-deficient design gets."""
    from scipy.linalg import lstsq
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    th = lstsq(X / sc, y, cond=1e-10, lapack_driver="gelsy", check_finite=False)[0]
    return th / sc


def _lstsq(X, y):
    """Least squares on unit-RMS columns: Cholesky of the normal equations, then iterative refinement on the
    residual of the full design; the pivoted QR (:func:`_lstsq_qr`) when the scaled Gram matrix is worse
    conditioned than ``ARX_COND_MAX`` or not positive definite.

    Why: the ARX designs are tall and narrow (up to 400 k rows, at most 15 columns); gelsy's column-pivoted QR
    of the rows took 0.8 to 2 s per fit, the Gram matrix and its k x k Cholesky take a few tens of ms. The
    normal equations alone square the condition number (lagged outputs at 10 kHz: cond(X) about 2e4, so an
    error of about 1e-8 relative); each refinement step ``th += G^-1 X'(y - X th)`` shrinks that error by a
    factor of about cond(G) eps (4e-8 here) down to a floor of about cond(X) eps, since the residual is computed in
    working precision (round 15: on an AMD EPYC's OpenBLAS, two steps left an order-2 ARX design of cond(X) 5e5 at
    1.6e-11 from the QR, which the ARX's unit-gain normalization carried to 1.3e-10 in b; a third step 8e-11, a
    residual in extended precision 3e-13 at three times the cost; tests/host/test_diagnose_speed_equivalence.py)."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    Xs = X / sc
    G = Xs.T @ Xs
    try:
        if not np.all(np.isfinite(G)) or np.linalg.cond(G) > ARX_COND_MAX:
            return _lstsq_qr(X, y)
        cf = cho_factor(G, check_finite=False)
    except LinAlgError:
        return _lstsq_qr(X, y)
    th = cho_solve(cf, Xs.T @ y, check_finite=False)
    for _ in range(ARX_REFINE_STEPS):
        th = th + cho_solve(cf, Xs.T @ (y - Xs @ th), check_finite=False)
    return th / sc


def _arx(x_list, y_list, order, rows, fast: bool = False):
    """ARX fit y[k] + a1 y[k-1].. = b0 x[k] + .. + b_n x[k-n] + c; returns (b, a) or None. ``fast``: the refined
    normal equations (:func:`_lstsq`) instead of the pivoted QR (:func:`_lstsq_qr`)."""
    if order == 0:
        return np.array([1.0]), np.array([1.0])
    Xs, ys = [], []
    for x, y in zip(x_list, y_list):
        n = y.size
        k = np.arange(order, n)
        if rows is not None and k.size > rows:
            k = k[:: int(np.ceil(k.size / rows))]
        cols = [-y[k - i] for i in range(1, order + 1)] + [x[k - i] for i in range(0, order + 1)]
        cols.append(np.ones(k.size))
        Xs.append(np.column_stack(cols))
        ys.append(y[k])
    th = (_lstsq if fast else _lstsq_qr)(np.vstack(Xs), np.concatenate(ys))
    a = np.concatenate([[1.0], th[:order]])
    b = th[order: 2 * order + 1]
    if np.any(np.abs(np.roots(a)) >= 0.9999) or abs(np.sum(b)) < 1e-12:
        return None
    b = b * (np.sum(a) / np.sum(b))  # unit static gain: H carries the gain
    return b, a


def _sim_rmse(m, xs, ys, k0s) -> float:
    err = sum(float(np.sum((filt(m[0], m[1], x) - y)[k0:] ** 2)) for x, y, k0 in zip(xs, ys, k0s))
    return float(np.sqrt(err / sum(y.size - k0 for y, k0 in zip(ys, k0s))))


def _oe_refine(m, xs, ys, k0s, max_nfev: int = 30):
    """Output-error refinement of an ARX model (b, a): least squares on the simulation error."""
    b0, a0 = m
    n = a0.size - 1
    stride = max(1, int(np.ceil(sum(y.size for y in ys) / 100_000)))

    def unpack(z):
        a = np.concatenate([[1.0], z[:n]])
        b = z[n:]
        return b * (np.sum(a) / np.sum(b)), a

    def resid(z):
        b, a = unpack(z)
        if np.any(np.abs(np.roots(a)) >= 0.9999):
            return np.full(sum((y.size - k0 + stride - 1) // stride for y, k0 in zip(ys, k0s)), 1e3)
        return np.concatenate([(filt(b, a, x) - y)[k0::stride] for x, y, k0 in zip(xs, ys, k0s)])

    z0 = np.concatenate([a0[1:], b0])
    try:
        sol = optimize.least_squares(resid, z0, max_nfev=max_nfev, x_scale="jac")
    except (ValueError, np.linalg.LinAlgError):
        return m
    if np.sum(resid(sol.x) ** 2) < np.sum(resid(z0) ** 2):
        return unpack(sol.x)
    return m


_DYN_CACHE: "collections.OrderedDict" = collections.OrderedDict()
_DYN_CACHE_MAX = 512      # entries (each two short coefficient vectors)


def _digest(arrays) -> tuple:
    """(size, BLAKE2b-128 of the float64 bytes) per array: a key that stands for the data exactly (a collision
    has probability 2^-128; 5 ms per 4 MB)."""
    out = []
    for x in arrays:
        x = np.ascontiguousarray(x, dtype=float)
        out.append((x.size, hashlib.blake2b(x.view(np.uint8), digest_size=16).digest()))
    return tuple(out)


def fit_dynamics(xs, ys, k0s, max_rows: int = 60_000, band: float | None = None,
                 orders=ORDERS) -> tuple[np.ndarray, np.ndarray]:
    """Dynamics G (unit static gain) from H outputs ``xs`` [um] to outputs ``ys`` [um] (offset removed).

    ARX of order 0, 2, 4 or 6 by the base model's rule (a higher order kept when it lowers
    the simulation error on these data by 5 % and is plausible); no output-error refinement
    (this is called once per setting of a drive-side term, so it must be cheap).

    band : float, optional
        The calibration's band [cycles/sample] for the plausibility rule (default: from ``xs``).
    orders : tuple of int
        ARX orders to choose from (the first is the fallback).

    Returns
    -------
    (b, a) : tuple of ndarray
        Discrete transfer function at the recordings' rate (read-only: the result is cached, keyed on a
        digest of the data, so a drive-side setting the diagnosis tries again, in the other fold's model or
        a later round whose model differs only after the dynamics, costs no fit).
    """
    key = (_digest(xs), _digest(ys), tuple(int(k) for k in k0s), int(max_rows),
           None if band is None else float(band), tuple(int(o) for o in orders))
    hit = _DYN_CACHE.get(key)
    if hit is None:
        (b, a), _, _ = _select_dynamics(xs, ys, k0s, max_rows, refine=False, band=band, orders=orders, fast=True)
        hit = (np.asarray(b, float), np.asarray(a, float))
        for x in hit:
            x.setflags(write=False)
        _DYN_CACHE[key] = hit
        while len(_DYN_CACHE) > _DYN_CACHE_MAX:
            _DYN_CACHE.popitem(last=False)
    _DYN_CACHE.move_to_end(key)
    return hit


def _select_dynamics(xs, ys, k0s, max_rows, refine, band=None, orders=ORDERS, fast=False):
    """ARX of each order in ``orders`` (output-error refined when ``refine``); returns ((b, a), order, scores).

    ``fast``: the ARX by the refined normal equations (:func:`_lstsq`, the same model to about 1e-12 relative)
    and, with a single order and no refinement, no simulation score (nothing to choose between). The base fit
    keeps the pivoted QR: its output-error refinement (30 steps of a trust-region search from the ARX) carries a
    1e-12 change of its starting point to 1e-5 of the base's held-out NRMSE (measured on s0-017)."""
    models, scores = {}, {}
    for order in orders:
        m = _arx([x[k0:] for x, k0 in zip(xs, k0s)], [y[k0:] for y, k0 in zip(ys, k0s)], order, max_rows, fast)
        models[order] = m
        if fast and len(orders) == 1 and not refine:
            scores[order] = float("nan") if m is not None else float("inf")
        else:
            scores[order] = _sim_rmse(m, xs, ys, k0s) if m is not None else float("inf")
    band = band_cps(xs, k0s) if band is None else band

    def pick():
        best = orders[0]
        for order in orders[1:]:
            if plausible(models[order], band) and scores[order] < 0.95 * scores[best]:
                best = order
        return best

    best = pick()
    if refine:   # output-error refinement of the chosen order and the next (the costly part: a simulation per step)
        for order in (best, min(best + 2, orders[-1])):
            if order > 0 and models[order] is not None:
                m = _oe_refine(models[order], xs, ys, k0s)
                # a refinement that makes a plausible model implausible is not taken: it would drop the
                # identified dynamics altogether (an own-stage creep case lost its 600 Hz mode to order 0)
                if plausible(m, band) or not plausible(models[order], band):
                    models[order] = m
                    scores[order] = _sim_rmse(m, xs, ys, k0s)
        best = pick()
    if models[best] is None:   # no stable fit of the only order asked for: static
        return (np.array([1.0]), np.array([1.0])), 0, scores
    return models[best], best, scores


def _gram(blocks):
    """(A, b, yy, n) of the normal equations from (X, y) row blocks."""
    A = sum(X.T @ X for X, _ in blocks)
    b = sum(X.T @ y for X, y in blocks)
    return A, b, sum(float(y @ y) for _, y in blocks), sum(y.size for _, y in blocks)


def _cv_score(Xs, yr, folds, layout, ridge_list, sign=0.0):
    """Held-out RMS [um] of the 2-fold fit for each ridge in ``ridge_list`` (plays monotone in ``sign``)."""
    grams = [_gram([(X[f == k], y[f == k]) for X, y, f in zip(Xs, yr, folds)]) for k in (0, 1)]
    Om = smoothness_penalty(layout, Xs[0].shape[1] - layout.n_cols)
    out = []
    for ridge in ridge_list:
        sse, n = 0.0, 0
        for k in (0, 1):
            A, b, _, _ = grams[k]
            th = _plane_solve(A, b, ridge, Om, layout, sign)
            for X, y, f in zip(Xs, yr, folds):
                t = f != k
                sse += float(np.sum((X[t] @ th - y[t]) ** 2))
                n += int(np.sum(t))
        out.append(float(np.sqrt(sse / max(n, 1))))
    return out


def reversal_levels(vs, k0s, deadband: float = 0.02, resolution: float = 1.0 / 32) -> int:
    """Distinct levels [count] at which the drive reversed during the settled calibration: turning points of a
    play of threshold ``deadband`` (normalized drive; noise on a measured drive makes no reversals), rounded
    to ``resolution`` of the normalized span 2, minima and maxima counted apart.

    A Preisach plane is identified only where reversals happened: a periodic calibration (one loop, two
    levels) determines the major loop and nothing of how the density splits across play thresholds, and
    cross-validation over its time blocks cannot tell (every block repeats the same loop)."""
    levels = set()
    for v, k0 in zip(vs, k0s):
        p = play_states(np.asarray(v, float)[k0:], [deadband], float(v[k0]))[:, 0]
        d = np.sign(np.diff(p))
        for i in turning_points(p):                                # first step in the new direction
            levels.add((int(d[i] > 0), int(np.round(p[i] / (2.0 * resolution)))))
    return len(levels)


def _output_sign(vs, ys, k0s) -> float:
    """+1 when the output rises with the drive over the settled calibration (the slope of a straight-line fit),
    else -1: the direction in which every play's function is monotone."""
    v = np.concatenate([np.asarray(v, float)[k0:] for v, k0 in zip(vs, k0s)])
    y = np.concatenate([np.asarray(y, float)[k0:] for y, k0 in zip(ys, k0s)])
    return 1.0 if float(np.dot(v - v.mean(), y - y.mean())) >= 0.0 else -1.0


def _path_points(v, rows) -> np.ndarray:
    """Indices that keep the drive's path: ``rows``, every turning point, the first and the last sample. Plays
    and the Bouc-Wen state are exact on this subsequence (rate independent, and exact for any step within a
    monotone run), so the size search runs on it instead of every sample."""
    return np.unique(np.concatenate([rows, turning_points(v), [0, v.size - 1]]).astype(np.intp))


def _cv_sizes(vs, v_rest, ys, qs, k0s, spans, r_all, sign=0.0):
    """Cross-validated choice of (R, K, ridge, Bouc-Wen column) on the quasi-static rows: returns
    (layout, ridge, table). The operators run on the drive's path points only (:func:`_path_points`)."""
    ns = [y.size for y in ys]
    Ts = _trends(ns, k0s)
    rows = [_strided(q, max(1000, CV_ROWS // len(ys))) for q in qs]
    folds = [block_masks(n, CV_BLOCKS)[r] % 2 for n, r in zip(ns, rows)]
    m = TREND_ORDER
    for i, (n, k0, r) in enumerate(zip(ns, k0s, rows)):
        # a recording whose quasi-static rows fall in fewer than half of its blocks (a chirp: only its slow
        # start) cannot identify a trend over its whole span; fitted on one fold, the trend extrapolates to
        # the other (61 um held-out error on a foreign case's chirp)
        if np.unique(block_masks(n, CV_BLOCKS)[r]).size < CV_BLOCKS // 2:
            Ts[i][:, i * m:(i + 1) * m] = 0.0
    yr = [y[r] for y, r in zip(ys, rows)]
    keep = [_path_points(v, r) for v, r in zip(vs, rows)]
    pos = [np.searchsorted(k, r) for k, r in zip(keep, rows)]
    vk = [np.ascontiguousarray(v[k]) for v, k in zip(vs, keep)]
    Pk = [play_states(v, r_all, v_rest) for v in vk]

    def design(lay):
        return [np.column_stack([plane_columns(P, lay, p, v, v_rest), T[r], np.ones(r.size)])
                for P, v, T, r, p in zip(Pk, vk, Ts, rows, pos)]

    # the Bouc-Wen column's shape, with the reversible curve alone (R = 1): a grid, then Nelder-Mead on
    # (log beta, gamma / beta)
    def bw_score(z):
        beta, gr = float(np.exp(z[0])), float(np.clip(z[1], -0.95, 0.95))
        lay = PlaneLayout(1, PLANE_KNOTS[0], spans, r_all, bw=(beta, gr * beta))
        return min(_cv_score(design(lay), yr, folds, lay, RIDGES[:2], sign))
    grid = [(bw_score((np.log(b), g)), (np.log(b), g)) for b in BW_BETAS for g in BW_GAMMA_RATIOS]
    sc0, z0 = min(grid)
    z0 = np.array(z0)
    sol = optimize.minimize(bw_score, z0, method="Nelder-Mead",
                            options={"maxfev": 40, "xatol": 0.01, "fatol": 1e-4 * sc0,
                                     "initial_simplex": [z0, z0 + [0.25, 0.0], z0 + [0.0, 0.15]]})
    z = sol.x if sol.fun < sc0 else z0
    best_bw = (None, (float(np.exp(z[0])), float(np.clip(z[1], -0.95, 0.95)) * float(np.exp(z[0]))))
    # thresholds the calibration's reversals can resolve: at least two reversal levels per play threshold
    n_rev = reversal_levels(vs, k0s)
    plays = [R for R in PLANE_PLAYS if R == 1 or 2 * R <= n_rev]
    table, best = [], None
    for bw in (None, best_bw[1]):
        for R in plays:
            for K in PLANE_KNOTS:
                lay = PlaneLayout(R, K, spans, r_all, bw=bw)
                for ridge, score in zip(RIDGES, _cv_score(design(lay), yr, folds, lay, RIDGES, sign)):
                    table.append({"plays": R, "knots": K, "ridge": ridge, "bouc_wen": bw, "columns": lay.n_cols,
                                  "cv_rmse_um": score})
                    if best is None or score < best:
                        best = score
    # the smallest plane (fewest columns, then the largest ridge) within SIZE_TOLERANCE of the best
    ok = [t for t in table if t["cv_rmse_um"] <= SIZE_TOLERANCE * best]
    pick = min(ok, key=lambda t: (t["columns"], -t["ridge"]))
    return (PlaneLayout(pick["plays"], pick["knots"], spans, r_all, bw=pick["bouc_wen"]), pick["ridge"],
            {"reversal_levels": n_rev, "plays_allowed": plays, "table": table})


def _filtered_plane_columns(P, v, v_rest, layout, Gba) -> np.ndarray:
    """(samples, layout.n_cols): one recording's plane columns (each play's hat basis, then the Bouc-Wen state)
    filtered by G = ``Gba`` (b, a) over the whole recording, subnormal tails set to 0 (``dsp.flush_subnormal``)."""
    C = [flush_subnormal(filt(Gba[0], Gba[1], hat_basis(P[:, i], kn)[:, 1:]))
         for i, kn in zip(layout.index, layout.knots)]
    if layout.bw:
        C.append(flush_subnormal(filt(Gba[0], Gba[1], _bw_state(v, layout.bw, v_rest)))[:, None])
    return np.hstack(C)


def _fit_plane(Ps, vs, v_rest, layout, ridge, ys, k0s, Gba=None, max_rows=MAX_ROWS, sign=0.0, cols=None):
    """Knot values (coefficients, then the offset) of the plane, columns filtered by G = ``Gba`` (b, a) when
    given, on all settled samples (strided), with the trend columns (not returned). ``cols``: the recordings'
    :func:`_filtered_plane_columns` for this ``Gba`` when already computed (round 28: the last fit and
    :func:`_holdout_histories` share them; the same floats as filtering here)."""
    ns = [y.size for y in ys]
    Ts = _trends(ns, k0s)
    per = max(1000, max_rows // len(ys))
    blocks = []
    for j, (P, v, T, y, k0) in enumerate(zip(Ps, vs, Ts, ys, k0s)):
        rows = _strided(np.arange(y.size) >= k0, per)
        if Gba is None:
            C = plane_columns(P, layout, rows, v, v_rest)
        elif cols is not None:
            C = cols[j][rows]
        else:  # filter each play's columns over the whole recording, keep the strided rows (no subnormal tails)
            C = [flush_subnormal(filt(Gba[0], Gba[1], hat_basis(P[:, i], kn)[:, 1:])[rows])
                 for i, kn in zip(layout.index, layout.knots)]
            if layout.bw:
                C.append(flush_subnormal(filt(Gba[0], Gba[1], _bw_state(v, layout.bw, v_rest))[rows])[:, None])
            C = np.hstack(C)
        blocks.append((np.column_stack([C, T[rows], np.ones(rows.size)]), y[rows]))
    A, b, _, _ = _gram(blocks)
    th = _plane_solve(A, b, ridge, smoothness_penalty(layout, A.shape[0] - layout.n_cols), layout, sign)
    return np.concatenate([th[:layout.n_cols], th[-1:]])


def _plane_output(Ps, vs, v_rest, layout, th):
    """H output without offset [um] per recording."""
    vals = layout.values(th[:-1])
    out = []
    for P, v in zip(Ps, vs):
        h = np.zeros(P.shape[0])
        for i, kn, vv in zip(layout.index, layout.knots, vals):
            h += hat_basis(P[:, i], kn) @ vv
        if layout.bw:
            h += th[layout.n_plane] * _bw_state(v, layout.bw, v_rest)
        out.append(h)
    return out


def _holdout_histories(Ps, vs, v_rest, layout, ridge, ys, k0s, Gba, max_rows=MAX_ROWS, sign=0.0,
                       cols=None) -> list:
    """The base's error on calibration histories it did not see: each of ``HOLDOUT_SEGMENTS`` contiguous
    quarters of every calibration recording's settled part is left out in turn (of all recordings at once), the
    plane's knot values (size, ridge, Bouc-Wen shape and dynamics kept) are refitted on the rest and the
    recordings are simulated from their start; the same estimator on all rows is the reference (the error on
    histories it saw). Neither carries the calibration's trend columns. Only samples whose drive lies within
    the range the refit saw are scored (beyond it the model extrapolates, which ``diagnose`` reports apart).

    Returns
    -------
    list of dict
        Per held-out history: ``recording`` (index), ``segment`` (which refit: the quarter left out of every
        recording at once), ``start``, ``stop`` (sample range held out), ``resid``
        (measured - simulated over that range [um]), ``resid_in`` (the same with the reference fit) and
        ``scored`` (bool mask over the range).
    """
    n_rec = len(ys)
    # every play's columns through G once per recording (the refits only change which rows enter), without the
    # filters' subnormal tails: they made every refit's Gram matrix 10 to 50 times slower. ``cols``: these,
    # computed by the caller for its last plane fit (round 28)
    if cols is None:
        cols = [_filtered_plane_columns(P, v, v_rest, layout, Gba) for P, v in zip(Ps, vs)]
    per = max(1000, max_rows // n_rec)
    edges = [np.linspace(k0, y.size, HOLDOUT_SEGMENTS + 1).astype(int) for y, k0 in zip(ys, k0s)]

    def refit(fit_mask):
        # no trend columns here: a per-recording trend fitted on three quarters says nothing of the fourth, and
        # the reference fit below must be the same estimator on all rows
        blocks = []
        for j in range(n_rec):
            if np.any(fit_mask[j]):
                rows = _strided(fit_mask[j], per)
                blocks.append((np.column_stack([cols[j][rows], np.ones(rows.size)]), ys[j][rows]))
        A, bb, _, _ = _gram(blocks)
        th = _plane_solve(A, bb, ridge, smoothness_penalty(layout, A.shape[0] - layout.n_cols), layout, sign)
        v_fit = np.concatenate([vs[j][fit_mask[j]] for j in range(n_rec)])
        return th, v_fit.min(), v_fit.max()

    th_ref, _, _ = refit([np.arange(y.size) >= k0 for y, k0 in zip(ys, k0s)])
    out = []
    for k in range(HOLDOUT_SEGMENTS):
        fit_mask = [np.arange(y.size) >= k0 for y, k0 in zip(ys, k0s)]
        for j, e in enumerate(edges):
            fit_mask[j][e[k]:e[k + 1]] = False
        if not any(np.any(m) for m in fit_mask):
            continue
        th, lo, hi = refit(fit_mask)
        for i, e in enumerate(edges):
            a, b = int(e[k]), int(e[k + 1])
            if b - a < 16:
                continue
            yhat = cols[i][a:b] @ th[:layout.n_cols] + th[-1]
            y_in = cols[i][a:b] @ th_ref[:layout.n_cols] + th_ref[-1]
            v = vs[i][a:b]
            out.append({"recording": i, "segment": k, "start": a, "stop": b, "resid": ys[i][a:b] - yhat,
                        "resid_in": ys[i][a:b] - y_in, "scored": (v >= lo) & (v <= hi)})
    return out


def history_holdout(params: dict) -> list:
    """The held-out-history residuals computed by :func:`fit_base` (``holdout=True``), popped from ``params``."""
    return params.pop("_holdout", [])


@blas_threads(1)   # its BLAS calls are small: a second thread only waits for a busy core (docs/diagnose-speed.md)
def fit_base(recordings, max_rows: int = MAX_ROWS, u_rest: float = 0.0, settle_s: float = 0.5,
             holdout: bool = False) -> dict:
    """Fit the base model (kind ``refined`` without terms) to calibration recordings.

    Parameters
    ----------
    recordings : sequence of Recording
        Calibration data: ``t`` [s], ``u`` [V], ``y`` [um], one sample rate.
    max_rows : int
        Samples entering the joint least-squares problem (evenly strided).
    u_rest : float
        Rest drive [V] the stage starts from (plays relaxed there; 0 V at power-up).
    settle_s : float
        The first ``settle_s`` seconds of each recording [s] (the stage settling
        from an unknown state) do not enter the fits.
    holdout : bool
        Also compute the base's error on calibration histories it did not see
        (:func:`_holdout_histories`), returned under ``_holdout`` (not a model
        parameter: take it with :func:`history_holdout` before saving the model).

    Returns
    -------
    dict
        Parameters of kind ``refined`` (``terms`` empty) plus ``base_info``: the
        plane's size and its cross-validation table, the chosen dynamics order, the
        simulation RMS error per order and the band the dynamics were identified in.
    """
    if not recordings:
        raise IdentError("base model: no calibration recordings")
    fs = [r.sample_rate_hz for r in recordings]
    if max(fs) / min(fs) - 1 > 0.01:
        raise IdentError(f"base model: calibration recordings have different sample rates {fs}")
    fs0 = float(np.mean(fs))
    ys = [np.asarray(rec.y, float) for rec in recordings]
    k0s = [min(int(round(settle_s * fs0)), len(y) // 2) for y in ys]
    umin = min(float(np.min(r.u[k0:])) for r, k0 in zip(recordings, k0s))
    umax = max(float(np.max(r.u[k0:])) for r, k0 in zip(recordings, k0s))
    if umax - umin <= 0:
        raise IdentError("base model: the calibration drive is constant; nothing to identify")
    mid, half = 0.5 * (umax + umin), 0.5 * (umax - umin)
    v_rest = (u_rest - mid) / half
    vs = [(rec.u - mid) / half for rec in recordings]
    r_all = np.array(sorted({j / R for R in PLANE_PLAYS for j in range(R)}))
    # each play's range over the settled samples: its extremes lie at the drive's turning points
    spans = []
    for v, k0 in zip(vs, k0s):
        kp = _path_points(v, np.zeros(0, np.intp))
        P = play_states(np.ascontiguousarray(v[kp]), r_all, v_rest)[kp >= k0]
        spans.append((P.min(axis=0), P.max(axis=0)) if P.size else (np.full(r_all.size, np.inf),
                                                                    np.full(r_all.size, -np.inf)))
    spans = [(float(min(s[0][i] for s in spans)), float(max(s[1][i] for s in spans))) for i in range(r_all.size)]
    qs = [_quasi_static(v, 1.0 / fs0, k0) for v, k0 in zip(vs, k0s)]
    n_settled = sum(v.size - k0 for v, k0 in zip(vs, k0s))
    if sum(int(q.sum()) for q in qs) < max(200, QS_MIN_FRACTION * n_settled):
        # mostly fast (a 20 Hz FORC sweep: only the ramps' middles are slow, over a narrow band of the drive,
        # which cannot size a plane): size on every settled sample
        qs = [np.arange(v.size) >= k0 for v, k0 in zip(vs, k0s)]
    sign = _output_sign(vs, ys, k0s)   # every play's function monotone in the output's direction
    layout, ridge, table = _cv_sizes(vs, v_rest, ys, qs, k0s, spans, r_all, sign)
    r_used = np.array(sorted({r_all[i] for i in layout.index}))
    Ps = [play_states(v, r_used, v_rest) for v in vs]
    layout.index = [int(np.flatnonzero(r_used == r_all[i])[0]) for i in layout.index]
    th = _fit_plane(Ps, vs, v_rest, layout, ridge, ys, k0s, None, max_rows, sign)
    band = band_cps(_plane_output(Ps, vs, v_rest, layout, th), k0s)
    Gba, order, scores = (np.array([1.0]), np.array([1.0])), 0, {}
    cols = None
    for it in range(2):
        xs = _plane_output(Ps, vs, v_rest, layout, th)
        Gba, order, scores = _select_dynamics(xs, [y - th[-1] for y in ys], k0s, max_rows // 2, refine=it == 1,
                                              band=band)
        if it == 1 and holdout:   # the last fit's filtered columns, whole, for the held-out histories too
            cols = [_filtered_plane_columns(P, v, v_rest, layout, Gba) for P, v in zip(Ps, vs)]
        th = _fit_plane(Ps, vs, v_rest, layout, ridge, ys, k0s, Gba, max_rows, sign, cols)
    vals = layout.values(th[:-1])
    hyst = {"type": "plane", "r": list(map(float, layout.r)), "knots": [k.tolist() for k in layout.knots],
            "values": [v.tolist() for v in vals], "offset": float(th[-1]), "v_rest": float(v_rest),
            "v_lo": -1.0, "v_hi": 1.0}
    if layout.bw:
        hyst["bw"] = {"beta": float(layout.bw[0]), "gamma": float(layout.bw[1]), "c_h": float(th[layout.n_plane])}
    info = {"plane": {"plays": layout.n_plays, "knots": layout.n_knots, "ridge": ridge, "columns": layout.n_cols,
                      "bouc_wen": layout.bw,
                      "cv_table": table["table"], "reversal_levels": table["reversal_levels"],
                      "plays_allowed": table["plays_allowed"],
                      "quasi_static_fraction": float(sum(int(q.sum()) for q in qs) /
                                                     max(sum(v.size - k0 for v, k0 in zip(vs, k0s)), 1))},
            "dynamics_order": order, "cv_sim_rmse_um": {str(k): v for k, v in scores.items()},
            "dynamics_band_hz": float(min(2.0 * band, 0.5) * fs0),
            "dynamics_note": (f"the dynamics were identified below about {min(2.0 * band, 0.5) * fs0:.0f} Hz "
                              "(twice the band holding 99 % of the calibration's H increments); above it the "
                              "calibration says nothing and |G| is only held at most "
                              f"{G_OUT_MAX:g}")}
    out = {"fs_hz": fs0, "u_mid": mid, "u_half": half, "hysteresis": hyst,
           "dynamics": {"b": np.asarray(Gba[0]).tolist(), "a": np.asarray(Gba[1]).tolist()},
           "terms": {}, "base_info": info}
    if holdout:
        out["_holdout"] = _holdout_histories(Ps, vs, v_rest, layout, ridge, ys, k0s, Gba, max_rows, sign, cols)
    return out
