"""float64 reference of the Krasnosel'skii-Pokrovskii (KP) kernel family.

Three models share one discretized Preisach plane (:class:`KPGrid`):

- **KP model**: ``y[k] = sum_j psi_j[k] * w_j`` with one KP operator per cell.
- **RKP model**: the same operators, with a density that depends on the input
  rate, ``w[k] = Theta F(rate[k])`` (Gaussian radial basis functions of a
  low-pass filtered rate estimate).
- **DCC law**: the KP compensation operators ``Psi_j`` (``psi_j + Psi_j = u``)
  and the direct compensation law ``u[k] = g (yd[k] + Psi(u[k-1]) . w)``.

The firmware kernels (``firmware/core/kp.c``, ``rkp.c``, ``dcc.c``) compute the
same equations in fixed point; ``piezoctl.golden.kp``/``rkp``/``dcc`` are their
bit-exact integer models. ``docs/kernels-kp.md`` has the equations, the cell
convention and the fixed-point formats.

Units: the input ``u`` and the thresholds are normalized drive, full scale
[-1, 1) (the q15 range); operator outputs share the input's units, in
[0, nmax]. Rates are in full scale per second [FS/s]; ``dt`` in seconds.

Conventions (the firmware's too):

- Cells: with levels ``n_i = nmin + (nmax - nmin)(i - 1)/L``, ``i = 1..L+1``,
  cell ``(i, j)``, ``1 <= i <= j <= L``, covers ``n1 in [n_i, n_i+1]``,
  ``n2 in [n_j, n_j+1]``; its operator uses the interval midpoints
  ``n1 = nmin + (i - 1/2) h``, ``n2 = nmin + (j - 1/2) h``, ``h = (nmax - nmin)/L``.
  Operators are numbered row by row: ``(1,1), (1,2), ..., (1,L), (2,2), ...``.
- Reset state: every operator at 0 and the previous input at ``nmin`` (the
  input has rested at the bottom of the plane, where every operator is 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal as _signal

__all__ = [
    "KPGrid", "kp_grid", "ridge", "ridge_o", "kp_outputs", "kp_model",
    "kp_compensation_outputs", "dcc_law", "dcc_gain",
    "lowpass_coefficient", "rate_estimate", "gaussian_rbf", "rate_features",
    "rkp_density", "rkp_model",
]

_CHUNK = 16384  # samples per block where a (T, N) intermediate is not needed


@dataclass(frozen=True)
class KPGrid:
    """Discretized Preisach plane: one KP operator per cell.

    Attributes
    ----------
    L : int
        Number of intervals per axis (L + 1 cutting levels).
    nmin, nmax : float
        Plane limits [normalized drive, FS]; ``nmax`` is also the ridge height.
    s : float
        Ridge width [FS]: the ridge rises from 0 to ``nmax`` over ``[0, s]``.
    n1, n2 : ndarray of float, shape (N,)
        Falling and rising thresholds of each operator [FS], ``n1 <= n2``,
        ``N = L (L + 1) / 2``.
    """

    L: int
    nmin: float
    nmax: float
    s: float
    n1: np.ndarray
    n2: np.ndarray

    @property
    def N(self) -> int:
        """Number of operators, ``L (L + 1) / 2``."""
        return int(self.n1.shape[0])

    @property
    def slope(self) -> float:
        """Ridge slope ``nmax / s`` [1]."""
        return self.nmax / self.s


def kp_grid(L: int, nmin: float = -1.0, nmax: float = 1.0, s: float | None = None) -> KPGrid:
    """Discretize the Preisach plane ``nmin <= n1 <= n2 <= nmax`` into KP cells.

    Parameters
    ----------
    L : int
        Intervals per axis, ``L >= 1``; gives ``N = L (L + 1) / 2`` operators.
    nmin, nmax : float
        Plane limits [FS], ``nmin < nmax``, ``nmax > 0`` (``nmax`` is the
        ridge height, the largest operator output).
    s : float, optional
        Ridge width [FS], ``s > 0``. Default ``(nmax - nmin) / (L - 1)``, the
        paper's ``1 / (L - 1)`` on a plane scaled to unit width (``nmax - nmin``
        for ``L = 1``).

    Returns
    -------
    KPGrid
        Operators at the midpoints of their cells (see the module docstring).

    Examples
    --------
    >>> g = kp_grid(3)
    >>> g.N
    6
    >>> [(round(float(a), 4), round(float(b), 4)) for a, b in zip(g.n1[:3], g.n2[:3])]
    [(-0.6667, -0.6667), (-0.6667, 0.0), (-0.6667, 0.6667)]
    """
    L = int(L)
    if L < 1:
        raise ValueError(f"L must be >= 1, got {L}")
    nmin = float(nmin)
    nmax = float(nmax)
    if not nmin < nmax:
        raise ValueError(f"need nmin < nmax, got {nmin}, {nmax}")
    if not nmax > 0.0:
        raise ValueError(f"nmax is the ridge height and must be > 0, got {nmax}")
    if s is None:
        s = (nmax - nmin) / (L - 1) if L > 1 else nmax - nmin
    s = float(s)
    if not s > 0.0:
        raise ValueError(f"ridge width s must be > 0, got {s}")
    h = (nmax - nmin) / L
    i, j = np.triu_indices(L)          # row by row: (0,0), (0,1), ..., (1,1), ...
    mid = nmin + (np.arange(L) + 0.5) * h
    n1 = mid[i].copy()
    n2 = mid[j].copy()
    n1.flags.writeable = False
    n2.flags.writeable = False
    return KPGrid(L=L, nmin=nmin, nmax=nmax, s=s, n1=n1, n2=n2)


def ridge(x, grid: KPGrid):
    """Ridge function ``r(x) = clip(nmax x / s, 0, nmax)`` [FS].

    Parameters
    ----------
    x : float or ndarray
        Input minus threshold [FS].
    grid : KPGrid
    """
    return np.clip(np.asarray(x, dtype=np.float64) * grid.slope, 0.0, grid.nmax)


def ridge_o(x, grid: KPGrid):
    """Complementary ridge ``ro(x) = x - r(x)`` [FS] of the compensation operator."""
    x = np.asarray(x, dtype=np.float64)
    return x - ridge(x, grid)


def _directions(u: np.ndarray, u_prev: float) -> np.ndarray:
    """Per-sample direction +1/-1, zeros (unchanged input) filled forward.

    Leading samples equal to ``u_prev`` stay 0 (hold). Works on floats and ints.
    """
    d = np.sign(np.diff(u, prepend=u_prev)).astype(np.int8)
    idx = np.where(d != 0, np.arange(d.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, d[np.maximum(idx, 0)], 0).astype(np.int8)


def _runs(u: np.ndarray, u_prev):
    """Yield ``(k0, k1, direction)`` runs of constant filled direction."""
    d = _directions(u, u_prev)
    if d.size == 0:
        return
    cut = np.flatnonzero(d[1:] != d[:-1]) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [d.size]])
    for k0, k1 in zip(starts.tolist(), ends.tolist()):
        yield k0, k1, int(d[k0])


def _kp_block(u, u_prev, psi, grid, out):
    """Advance the operators over ``u``; writes ``out`` (T, N), returns last psi.

    Within a run where the input does not fall, ``max(psi[k-1], r(u[k] - n2))``
    equals ``max(psi_start, r(u[k] - n2))`` because ``r`` is non-decreasing, so a
    whole run is one vectorized operation (identical, bit for bit, to the
    sample-by-sample recursion). The ridge values are computed per block of
    samples, so a reversal every sample costs one numpy call per sample.
    """
    for a in range(0, u.size, _CHUNK):
        seg = u[a:a + _CHUNK]
        r2 = ridge(seg[:, None] - grid.n2, grid)
        r1 = ridge(seg[:, None] - grid.n1, grid)
        o = out[a:a + seg.size]
        for k0, k1, d in _runs(seg, u_prev):
            if d > 0:
                np.maximum(psi, r2[k0:k1], out=o[k0:k1])
            elif d < 0:
                np.minimum(psi, r1[k0:k1], out=o[k0:k1])
            else:
                o[k0:k1] = psi
            psi = o[k1 - 1]
        u_prev = seg[-1]
    return np.array(psi, dtype=np.float64, copy=True)


def _initial(u, grid, psi0, u_prev):
    u = np.asarray(u, dtype=np.float64).ravel()
    psi = np.zeros(grid.N) if psi0 is None else np.asarray(psi0, dtype=np.float64).ravel().copy()
    if psi.shape != (grid.N,):
        raise ValueError(f"psi0 must have shape ({grid.N},), got {psi.shape}")
    up = grid.nmin if u_prev is None else float(u_prev)
    return u, psi, up


def kp_outputs(u, grid: KPGrid, psi0=None, u_prev: float | None = None) -> np.ndarray:
    """Output of every KP operator at every sample.

    Per operator ``j`` (thresholds ``n1_j <= n2_j``), at sample ``k``:

    - ``u[k] > u[k-1]``: ``psi[k] = max(psi[k-1], r(u[k] - n2_j))``
    - ``u[k] < u[k-1]``: ``psi[k] = min(psi[k-1], r(u[k] - n1_j))``
    - otherwise ``psi[k] = psi[k-1]``

    Vectorized over operators and over monotone runs of the input; the Python
    loop runs once per input reversal.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    grid : KPGrid
    psi0 : array_like, shape (N,), optional
        Operator outputs before the first sample [FS]; default zeros.
    u_prev : float, optional
        Input before the first sample [FS]; default ``grid.nmin``.

    Returns
    -------
    ndarray, shape (T, N)
        ``psi[k, j]`` [FS], in ``[0, nmax]`` when ``psi0`` is.
    """
    u, psi, up = _initial(u, grid, psi0, u_prev)
    out = np.empty((u.size, grid.N))
    _kp_block(u, up, psi, grid, out)
    return out


def kp_model(u, grid: KPGrid, w, psi0=None, u_prev: float | None = None) -> np.ndarray:
    """KP model output ``y[k] = sum_j psi_j[k] w_j``.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    grid : KPGrid
    w : array_like, shape (N,)
        Density (weights) [output units per FS of operator output].
    psi0, u_prev
        Initial state, as in :func:`kp_outputs`.

    Returns
    -------
    ndarray, shape (T,)
        Model output [output units].
    """
    u, psi, up = _initial(u, grid, psi0, u_prev)
    w = np.asarray(w, dtype=np.float64).ravel()
    if w.shape != (grid.N,):
        raise ValueError(f"w must have shape ({grid.N},), got {w.shape}")
    y = np.empty(u.size)
    buf = np.empty((min(u.size, _CHUNK), grid.N))
    for a in range(0, u.size, _CHUNK):
        seg = u[a:a + _CHUNK]
        o = buf[:seg.size]
        psi = _kp_block(seg, up, psi, grid, o)
        up = seg[-1]
        y[a:a + seg.size] = o @ w
    return y


# ------------------------------------------------------------ compensation / DCC

def _comp_block(u, state, grid, out):
    """Compensation operators over ``u``; ``state`` = dict(v_prev, xi, zo, cpsi, dir)."""
    for k0, k1, d in _runs(u, state["v_prev"]):
        if d == 0:
            out[k0:k1] = state["cpsi"]
        else:
            if d != state["dir"]:  # reversal: remember input and output there
                state["xi"] = state["v_prev"] if k0 == 0 else u[k0 - 1]
                state["zo"] = np.array(state["cpsi"], copy=True)
                state["dir"] = d
            seg = u[k0:k1, None]
            lin = seg - state["xi"] + state["zo"]
            if d > 0:
                x = seg - grid.n2
                np.minimum(lin, ridge_o(x, grid) + grid.n2, out=out[k0:k1])
            else:
                x = seg - grid.n1
                np.maximum(lin, ridge_o(x, grid) + grid.n1, out=out[k0:k1])
        state["cpsi"] = out[k1 - 1]
    if u.size:
        state["v_prev"] = u[-1]
    state["cpsi"] = np.array(state["cpsi"], copy=True)


def _comp_state(grid, psi0, u_prev):
    psi = np.zeros(grid.N) if psi0 is None else np.asarray(psi0, dtype=np.float64).ravel()
    if psi.shape != (grid.N,):
        raise ValueError(f"psi0 must have shape ({grid.N},), got {psi.shape}")
    up = grid.nmin if u_prev is None else float(u_prev)
    cpsi = up - psi
    # Reset state: falling, last reversal at the initial input.
    return {"v_prev": up, "xi": up, "zo": cpsi.copy(), "cpsi": cpsi, "dir": -1}


def kp_compensation_outputs(u, grid: KPGrid, psi0=None, u_prev: float | None = None) -> np.ndarray:
    """Output of every KP compensation operator ``Psi_j`` at every sample.

    With ``xi`` the input and ``zo_j`` the operator output at the last input
    reversal, and ``ro(x) = x - r(x)``:

    - rising: ``Psi = min(u - xi + zo, ro(u - n2) + n2)``
    - falling: ``Psi = max(u - xi + zo, ro(u - n1) + n1)``
    - unchanged input: ``Psi[k] = Psi[k-1]``

    so that ``psi_j + Psi_j = u`` for the KP operators of :func:`kp_outputs`
    started from the same state. The initial state is a falling branch whose
    last reversal is the initial input: ``xi = u_prev``, ``zo = u_prev - psi0``.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    grid : KPGrid
    psi0 : array_like, shape (N,), optional
        KP operator outputs before the first sample [FS]; default zeros.
    u_prev : float, optional
        Input before the first sample [FS]; default ``grid.nmin``.

    Returns
    -------
    ndarray, shape (T, N)
        ``Psi[k, j]`` [FS].
    """
    u = np.asarray(u, dtype=np.float64).ravel()
    st = _comp_state(grid, psi0, u_prev)
    out = np.empty((u.size, grid.N))
    _comp_block(u, st, grid, out)
    return out


def dcc_gain(w) -> float:
    """Default DCC gain ``g = 1 / sum(w)`` [1]; raises if ``sum(w) <= 0``."""
    tot = float(np.sum(np.asarray(w, dtype=np.float64)))
    if not tot > 0.0:
        raise ValueError(f"the density must sum to a positive value, got {tot}")
    return 1.0 / tot


def dcc_law(yd, grid: KPGrid, w, gain: float | None = None, psi0=None,
            u_prev: float | None = None, clip: tuple[float, float] | None = (-1.0, 1.0)) -> np.ndarray:
    """Direct compensation (DCC) law: the drive that makes the KP model follow ``yd``.

    ``u[k] = g (yd[k] + sum_j Psi_j(u[k-1]) w_j)``, clipped to ``clip``.

    The KP model is ``y = sum_j psi_j w_j = W u - Psi . w`` with
    ``W = sum_j w_j`` (because ``psi_j + Psi_j = u``), so ``g = 1/W`` inverts it;
    using ``Psi`` of the previous drive ``u[k-1]`` avoids the algebraic loop.
    ``yd`` is in the model's output units: identify ``w`` against displacement
    divided by the stage's static gain (drive units) and ``W`` is close to 1.

    Parameters
    ----------
    yd : array_like, shape (T,)
        Desired model output [output units].
    grid : KPGrid
    w : array_like, shape (N,)
        KP density.
    gain : float, optional
        ``g`` [FS per output unit]; default :func:`dcc_gain` ``(w) = 1 / sum(w)``.
    psi0, u_prev
        Initial operator state and drive, as in :func:`kp_compensation_outputs`.
    clip : (float, float) or None
        Drive limits [FS] applied to ``u[k]`` (the operators see the clipped
        drive); None for none.

    Returns
    -------
    ndarray, shape (T,)
        Drive ``u`` [FS].
    """
    yd = np.asarray(yd, dtype=np.float64).ravel()
    w = np.asarray(w, dtype=np.float64).ravel()
    if w.shape != (grid.N,):
        raise ValueError(f"w must have shape ({grid.N},), got {w.shape}")
    g = dcc_gain(w) if gain is None else float(gain)
    st = _comp_state(grid, psi0, u_prev)
    lo, hi = (-np.inf, np.inf) if clip is None else clip
    n1, n2, slope, nmax = grid.n1, grid.n2, grid.slope, grid.nmax
    cpsi, zo, xi, vp, dr = st["cpsi"], st["zo"], st["xi"], st["v_prev"], st["dir"]
    u_last = vp
    out = np.empty(yd.size)
    for k in range(yd.size):
        v = u_last
        if v != vp:
            d = 1 if v > vp else -1
            if d != dr:
                xi, zo, dr = vp, cpsi, d
            x = v - (n2 if d > 0 else n1)
            cand = x - np.clip(x * slope, 0.0, nmax) + (n2 if d > 0 else n1)
            lin = v - xi + zo
            cpsi = np.minimum(lin, cand) if d > 0 else np.maximum(lin, cand)
            vp = v
        u_last = min(max(g * (yd[k] + float(cpsi @ w)), lo), hi)
        out[k] = u_last
    return out


# ------------------------------------------------------------------------ RKP

def lowpass_coefficient(fc: float, dt: float) -> float:
    """Coefficient ``a = 1 - exp(-2 pi fc dt)`` of the rate filter.

    Parameters
    ----------
    fc : float
        Cutoff frequency [Hz]; ``inf`` gives 1 (no filtering).
    dt : float
        Sample period [s].
    """
    return float(1.0 - np.exp(-2.0 * np.pi * fc * dt))


def rate_estimate(u, dt: float, filt: float = 1.0, u_prev: float | None = None) -> np.ndarray:
    """Filtered input rate: first-order low-pass of the per-sample difference.

    ``d[k] = u[k] - u[k-1]``, ``q[k] = q[k-1] + a (d[k] - q[k-1])`` with
    ``q[-1] = 0``, and ``rate[k] = q[k] / dt``.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    dt : float
        Sample period [s].
    filt : float
        Filter coefficient ``a`` in (0, 1] (1: no filtering); see
        :func:`lowpass_coefficient`.
    u_prev : float, optional
        Input before the first sample [FS]; default ``u[0]`` (no initial step).

    Returns
    -------
    ndarray, shape (T,)
        Rate [FS/s].
    """
    u = np.asarray(u, dtype=np.float64).ravel()
    a = float(filt)
    if not 0.0 < a <= 1.0:
        raise ValueError(f"filter coefficient must be in (0, 1], got {a}")
    if u.size == 0:
        return np.zeros(0)
    up = u[0] if u_prev is None else float(u_prev)
    d = np.diff(u, prepend=up)
    q = _signal.lfilter([a], [1.0, -(1.0 - a)], d)
    return q / float(dt)


def gaussian_rbf(rate, centers, widths) -> np.ndarray:
    """Gaussian radial basis ``F_m = exp(-((rate - c_m) / sigma_m)^2 / 2)``.

    Parameters
    ----------
    rate : array_like, shape (T,)
        Rate [FS/s].
    centers, widths : array_like, shape (M,)
        Centers ``c_m`` and standard deviations ``sigma_m > 0`` [FS/s].

    Returns
    -------
    ndarray, shape (T, M)
    """
    rate = np.asarray(rate, dtype=np.float64).ravel()
    c = np.asarray(centers, dtype=np.float64).ravel()
    sg = np.asarray(widths, dtype=np.float64).ravel()
    if c.shape != sg.shape:
        raise ValueError("centers and widths must have the same length")
    if np.any(sg <= 0):
        raise ValueError("widths must be > 0")
    z = (rate[:, None] - c[None, :]) / sg[None, :]
    return np.exp(-0.5 * z * z)


def rate_features(u, dt: float, centers, widths, filt: float = 1.0,
                  u_prev: float | None = None) -> np.ndarray:
    """RKP rate features ``F(rate[k])``: Gaussians of the filtered input rate.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    dt : float
        Sample period [s].
    centers, widths : array_like, shape (M,)
        Gaussian centers and standard deviations [FS/s] (the paper uses M = 13).
    filt : float
        Rate filter coefficient ``a`` in (0, 1], see :func:`rate_estimate`.
    u_prev : float, optional
        Input before the first sample [FS]; default ``u[0]``.

    Returns
    -------
    ndarray, shape (T, M)
    """
    return gaussian_rbf(rate_estimate(u, dt, filt, u_prev), centers, widths)


def rkp_density(features, theta) -> np.ndarray:
    """Rate-dependent density ``w[k] = Theta F[k]``.

    Parameters
    ----------
    features : array_like, shape (T, M)
    theta : array_like, shape (N, M)
        ``theta[j, m]``: weight of Gaussian ``m`` in the density of operator ``j``.

    Returns
    -------
    ndarray, shape (T, N)
    """
    return np.asarray(features, dtype=np.float64) @ np.asarray(theta, dtype=np.float64).T


def rkp_model(u, grid: KPGrid, theta, dt: float, centers, widths, filt: float = 1.0,
              psi0=None, u_prev: float | None = None) -> np.ndarray:
    """Rate-dependent KP model ``y[k] = sum_j psi_j[k] w_j[k]``, ``w[k] = Theta F(rate[k])``.

    Parameters
    ----------
    u : array_like, shape (T,)
        Input [FS].
    grid : KPGrid
    theta : array_like, shape (N, M)
        Density coefficients.
    dt : float
        Sample period [s].
    centers, widths : array_like, shape (M,)
        Gaussian centers and standard deviations [FS/s].
    filt : float
        Rate filter coefficient ``a`` in (0, 1].
    psi0 : array_like, shape (N,), optional
        Initial operator outputs; default zeros.
    u_prev : float, optional
        Input before the first sample [FS], for the operators and the rate
        estimate alike; default ``grid.nmin`` (the firmware's reset state).

    Returns
    -------
    ndarray, shape (T,)
        Model output [output units].
    """
    u, psi, up = _initial(u, grid, psi0, u_prev)
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim != 2 or theta.shape[0] != grid.N:
        raise ValueError(f"theta must have shape ({grid.N}, M), got {theta.shape}")
    F = rate_features(u, dt, centers, widths, filt, up)
    y = np.empty(u.size)
    buf = np.empty((min(u.size, _CHUNK), grid.N))
    for a in range(0, u.size, _CHUNK):
        seg = u[a:a + _CHUNK]
        o = buf[:seg.size]
        psi = _kp_block(seg, up, psi, grid, o)
        up = seg[-1]
        y[a:a + seg.size] = np.einsum("tn,tn->t", o, F[a:a + seg.size] @ theta.T)
    return y
