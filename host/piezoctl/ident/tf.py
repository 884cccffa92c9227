"""Linear dynamics from frequency responses: WCLS and PSO-WCLS transfer-function fits.

The model is a continuous-time transfer function of order ``n``

.. math::

    D(s) = \\frac{b_{n_b} s^{n_b} + \\dots + b_0}{s^n + a_{n-1} s^{n-1} + \\dots + a_0},
    \\qquad n_b \\le n,

fitted to a measured frequency response :math:`H_i = A(\\omega_i) e^{j\\alpha(\\omega_i)}`.

WCLS (weighted complex least squares)
    Linear in the parameters :math:`\\Theta = [b_{n_b} \\dots b_0, a_{n-1} \\dots a_0]`:
    row :math:`X_i = [s_i^{n_b} \\dots 1, -H_i s_i^{n-1} \\dots -H_i]`, target
    :math:`Y_i = H_i s_i^n` (:math:`s_i = j\\omega_i`). With weights :math:`W \\ge 0`
    the real :math:`\\Theta` minimizing :math:`\\sum_i W_i |X_i\\Theta - Y_i|^2` is

    .. math::

        \\Theta = (X^T W \\bar X + \\bar X^T W X)^{-1}(\\bar X^T W Y + X^T W \\bar Y),

    i.e. :math:`2\\,\\mathrm{Re}(X^H W X)\\,\\Theta = 2\\,\\mathrm{Re}(X^H W Y)`. We solve the
    equivalent stacked real least-squares problem
    :math:`[\\mathrm{Re};\\mathrm{Im}](\\sqrt W X)\\Theta = [\\mathrm{Re};\\mathrm{Im}](\\sqrt W Y)`
    with ``numpy.linalg.lstsq`` (same solution, condition number not squared).

Frequency scaling
    Powers :math:`\\omega^k` over 0.01-50 Hz span 20 decades for :math:`k = 4`, so the
    fit is done in :math:`s' = s/\\omega_0` with :math:`\\omega_0 = \\max_i \\omega_i`
    [rad/s] (every :math:`|s'_i| \\le 1`), and each regressor column is divided by
    its norm before ``lstsq``. The scaled coefficients are unscaled by
    :math:`b_k = b'_k\\,\\omega_0^{\\,n-k}`, :math:`a_k = a'_k\\,\\omega_0^{\\,n-k}`
    (which keeps the denominator monic).

PSO-WCLS (stable models)
    If WCLS returns a pole with positive real part, that pole is reflected across the
    imaginary axis (:math:`p \\to -\\bar p`), the denominator recomputed from the poles,
    and a particle swarm searches the (scaled) denominator coefficients in
    :math:`a'_i(1 \\pm \\text{spread})`. For each particle the numerator is the linear
    least-squares fit of the relative error :math:`(N/A - H)/|H|`; the fitness is

    .. math::

        T_e = \\frac{1}{N} \\sum_i \\frac{|D(j\\omega_i) - H_i|}{|H_i|}

    (mean relative complex error, normalized by the measured magnitude at each
    frequency). A particle whose denominator has a root with real part >= 0 is
    discarded (infinite fitness). The inertia falls linearly from ``inertia[0]`` to
    ``inertia[1]``; the search stops at :math:`T_e \\le T_e^*` or after the last
    generation. The random generator is seeded, so a fit is reproducible.

Also here: :func:`pole_report` and :func:`resonance_hz` (poles in Hz with their
damping), :func:`freqresp`, :func:`discretize` and :func:`simulate_tf` (FOH or
ZOH simulation). :class:`FRF` and :func:`frf_from_time` live in
:mod:`piezoctl.ident.frf` and are re-exported here.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from .frf import FRF, frf_from_time  # re-exported: tf.FRF, tf.frf_from_time

__all__ = [
    "TFResult",
    "FRF",
    "freqresp",
    "relative_error",
    "wcls",
    "pso_wcls",
    "fit_tf",
    "frf_from_time",
    "discretize",
    "simulate_tf",
    "poles_of",
    "is_stable",
    "pole_report",
    "resonance_hz",
]


@dataclass
class TFResult:
    """A fitted continuous-time transfer function.

    Attributes
    ----------
    num : ndarray
        Numerator coefficients, descending powers of s [output unit / input unit * s^k].
    den : ndarray
        Denominator coefficients, descending powers of s, ``den[0] == 1``.
    te : float
        Mean relative error :math:`T_e` over the fitted frequencies [1].
    method : str
        ``"wcls"`` or ``"pso-wcls"``.
    info : dict
        Details: ``flipped`` (number of reflected poles), ``generations`` (PSO
        generations run), ``wcls_te``, ``seconds``.
    """

    num: np.ndarray
    den: np.ndarray
    te: float
    method: str
    info: dict = field(default_factory=dict)

    @property
    def poles(self) -> np.ndarray:
        """Poles [rad/s], complex."""
        return poles_of(self.den)

    @property
    def stable(self) -> bool:
        """True if every pole has a negative real part."""
        return is_stable(self.den)

    def to_dict(self) -> dict:
        """JSON-serializable form: ``num``, ``den``, ``poles`` ([[re, im], ...]), ``te``,
        ``poles_hz`` (:func:`pole_report`) and ``resonance_hz`` (:func:`resonance_hz`)."""
        p = self.poles
        return {
            "num": [float(v) for v in self.num],
            "den": [float(v) for v in self.den],
            "poles": [[float(z.real), float(z.imag)] for z in p],
            "poles_hz": pole_report(p),
            "resonance_hz": resonance_hz(p),
            "te": float(self.te),
            "method": self.method,
            "stable": bool(self.stable),
            "info": {k: (float(v) if isinstance(v, (np.floating, float)) else v)
                     for k, v in self.info.items()},
        }


def freqresp(num, den, w) -> np.ndarray:
    """Complex response of ``num(s)/den(s)`` at ``s = j w``.

    Parameters
    ----------
    num, den : array_like
        Coefficients, descending powers of s.
    w : array_like
        Angular frequencies [rad/s].
    """
    s = 1j * np.asarray(w, dtype=float)
    return np.polyval(num, s) / np.polyval(den, s)


def relative_error(h_model, h) -> float:
    """:math:`T_e` = mean of :math:`|h_{model} - h| / |h|` [1]."""
    h = np.asarray(h)
    return float(np.mean(np.abs(np.asarray(h_model) - h) / np.abs(h)))


def poles_of(den) -> np.ndarray:
    """Roots of the denominator [rad/s], sorted by real part then imaginary part."""
    den = np.atleast_1d(np.asarray(den, dtype=float))
    if den.size <= 1:
        return np.zeros(0, dtype=complex)
    p = np.roots(den).astype(complex)
    return p[np.lexsort((p.imag, p.real))]


def is_stable(den) -> bool:
    """True if every root of ``den`` has a strictly negative real part."""
    p = poles_of(den)
    return bool(np.all(p.real < 0.0))


def pole_report(poles) -> list[dict]:
    """Poles in Hz with their damping, one entry per real pole or complex pair.

    For a pole ``p`` [rad/s]: natural frequency ``f_hz = |p| / 2 pi`` [Hz] and
    damping ratio ``damping = -Re p / |p|`` [1] (1 for a stable real pole, -1 for
    an unstable one, below 0 for a growing oscillation). A complex pair is listed
    once (``pair: true``).

    Parameters
    ----------
    poles : array_like of complex
        Poles [rad/s].

    Returns
    -------
    list of dict
        ``f_hz``, ``damping``, ``pair``, sorted by ``f_hz``.
    """
    out = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag < 0:
            continue  # the conjugate of a listed pair
        mag = abs(p)
        out.append({"f_hz": float(mag / (2 * np.pi)),
                    "damping": float(-p.real / mag) if mag > 0 else 1.0,
                    "pair": bool(p.imag > 0)})
    return sorted(out, key=lambda r: r["f_hz"])


def resonance_hz(poles) -> float | None:
    """Natural frequency [Hz] of the least damped complex pole pair (the dominant mode).

    None when the model has no complex pair (no resonance).
    """
    pairs = [r for r in pole_report(poles) if r["pair"]]
    if not pairs:
        return None
    return min(pairs, key=lambda r: r["damping"])["f_hz"]


def _check_frf(w, h) -> tuple[np.ndarray, np.ndarray]:
    w = np.asarray(w, dtype=float).ravel()
    h = np.asarray(h, dtype=complex).ravel()
    if w.shape != h.shape:
        raise ValueError(f"w and h differ in length ({w.size} vs {h.size})")
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(h))):
        raise ValueError("frequency response has NaN or infinite values")
    if np.any(w <= 0) or np.any(np.diff(w) <= 0):
        raise ValueError("frequencies must be positive and strictly increasing")
    if np.any(np.abs(h) == 0):
        raise ValueError("frequency response has zero magnitude")
    return w, h


def _unscale(theta_num, theta_den_low, w0, n):
    """Scaled coefficients (descending) -> physical ones; denominator made monic."""
    nb = theta_num.size - 1
    num = np.array([theta_num[i] * w0 ** (n - (nb - i)) for i in range(nb + 1)])
    den = np.concatenate(([1.0], [theta_den_low[i] * w0 ** (i + 1) for i in range(n)]))
    return num, den


def _scale_den(den, w0):
    """Physical monic denominator -> scaled low coefficients a'_{n-1..0}."""
    den = np.asarray(den, dtype=float)
    n = den.size - 1
    return np.array([den[i + 1] / w0 ** (i + 1) for i in range(n)])


def wcls(w, h, n: int, n_num: int | None = None, weights=None) -> TFResult:
    """Weighted complex least-squares fit of an order-``n`` transfer function.

    Parameters
    ----------
    w : array_like
        Angular frequencies [rad/s], positive, strictly increasing.
    h : array_like of complex
        Measured response :math:`A e^{j\\alpha}` at ``w``.
    n : int
        Denominator order (>= 1).
    n_num : int, optional
        Numerator order, 0 <= n_num <= n (default ``n``).
    weights : array_like, optional
        Weights :math:`W_i \\ge 0` of the equation errors. Default
        :math:`1/|H_i|^2`, which makes each equation error
        :math:`A'(s'_i)\\,(D - H_i)/|H_i|` a relative error times the scaled denominator.

    Returns
    -------
    TFResult
        With ``method == "wcls"``; may be unstable.
    """
    t0 = time.perf_counter()
    w, h = _check_frf(w, h)
    n = int(n)
    nb = n if n_num is None else int(n_num)
    if n < 1 or not 0 <= nb <= n:
        raise ValueError(f"need n >= 1 and 0 <= n_num <= n (got n={n}, n_num={nb})")
    if 2 * w.size < nb + 1 + n:
        raise ValueError(f"{w.size} frequencies cannot determine {nb + 1 + n} parameters")
    wt = 1.0 / np.abs(h) ** 2 if weights is None else np.asarray(weights, dtype=float).ravel()
    if wt.shape != w.shape or np.any(wt < 0) or not np.all(np.isfinite(wt)):
        raise ValueError("weights must be finite, >= 0 and one per frequency")
    w0 = float(w.max())
    s = 1j * w / w0
    cols_b = [s ** k for k in range(nb, -1, -1)]
    cols_a = [-h * s ** k for k in range(n - 1, -1, -1)]
    x = np.column_stack(cols_b + cols_a)
    y = h * s ** n
    sw = np.sqrt(wt)
    xr = np.vstack([(sw[:, None] * x).real, (sw[:, None] * x).imag])
    yr = np.concatenate([(sw * y).real, (sw * y).imag])
    cn = np.linalg.norm(xr, axis=0)
    cn[cn == 0] = 1.0
    theta = np.linalg.lstsq(xr / cn, yr, rcond=None)[0] / cn
    num, den = _unscale(theta[: nb + 1], theta[nb + 1:], w0, n)
    te = relative_error(freqresp(num, den, w), h)
    return TFResult(num, den, te, "wcls", {"flipped": 0, "generations": 0, "wcls_te": te,
                                            "w0": w0, "seconds": time.perf_counter() - t0})


def wcls_normal_residual(w, h, n, theta_num, theta_den_low, weights=None) -> float:
    """Relative residual of the paper's WCLS normal equations (a self-check).

    Builds :math:`M = X^T W \\bar X + \\bar X^T W X` and
    :math:`v = \\bar X^T W Y + X^T W \\bar Y` in the scaled frequency
    :math:`s' = j\\omega/\\omega_0` and returns :math:`|M\\Theta - v| / |v|` for the
    scaled parameters. Used by the tests to show that :func:`wcls` solves the
    stated equations.

    Parameters
    ----------
    w, h, n, weights
        As for :func:`wcls` (numerator order = ``len(theta_num) - 1``).
    theta_num, theta_den_low : array_like
        Scaled parameters :math:`b'` (descending) and :math:`a'_{n-1} \\dots a'_0`.
    """
    w, h = _check_frf(w, h)
    nb = len(theta_num) - 1
    wt = 1.0 / np.abs(h) ** 2 if weights is None else np.asarray(weights, dtype=float)
    s = 1j * w / w.max()
    x = np.column_stack([s ** k for k in range(nb, -1, -1)] + [-h * s ** k for k in range(n - 1, -1, -1)])
    y = h * s ** n
    wd = wt[:, None]
    m = x.T @ (wd * np.conj(x)) + np.conj(x).T @ (wd * x)
    v = np.conj(x).T @ (wt * y) + x.T @ (wt * np.conj(y))
    th = np.concatenate([theta_num, theta_den_low])
    return float(np.linalg.norm(m @ th - v) / np.linalg.norm(v))


def _flip_unstable(den) -> tuple[np.ndarray, int]:
    p = np.roots(den)
    bad = p.real >= 0
    p = np.where(bad, -np.abs(p.real) - 1e-9 * np.abs(p) + 1j * p.imag, p)
    d = np.real(np.poly(p))
    return d, int(np.count_nonzero(bad))


def _num_for_den(s, h, den_low_scaled, nb):
    """Least-squares numerator (scaled) for a fixed scaled denominator; relative error."""
    n = den_low_scaled.size
    a = s ** n + sum(den_low_scaled[i] * s ** (n - 1 - i) for i in range(n))
    r = np.column_stack([s ** k for k in range(nb, -1, -1)]) / (a * np.abs(h))[:, None]
    tgt = h / np.abs(h)
    xr = np.vstack([r.real, r.imag])
    cn = np.linalg.norm(xr, axis=0)
    cn[cn == 0] = 1.0
    b = np.linalg.lstsq(xr / cn, np.concatenate([tgt.real, tgt.imag]), rcond=None)[0] / cn
    model = np.polyval(b, s) / a
    return b, float(np.mean(np.abs(model - h) / np.abs(h)))


def pso_wcls(w, h, n: int, n_num: int | None = None, weights=None, *, swarm: int = 100,
             generations: int = 20, spread: float = 0.5, inertia=(0.9, 0.4),
             c1: float = 2.0, c2: float = 2.0, te_target: float = 1e-3, seed: int = 0,
             always: bool = False) -> TFResult:
    """WCLS, then (if unstable) a particle-swarm search for a stable denominator.

    Parameters
    ----------
    w, h, n, n_num, weights
        As for :func:`wcls`.
    swarm : int
        Particles per generation (paper: 100).
    generations : int
        Maximum generations (paper: 20).
    spread : float
        Search range :math:`a'_i (1 \\pm spread)` around the reflected-pole
        denominator (paper: 0.5).
    inertia : (float, float)
        Inertia weight :math:`M_{max}, M_{min}`, falling linearly over the generations.
    c1, c2 : float
        Cognitive and social acceleration weights.
    te_target : float
        Stop when the best :math:`T_e \\le T_e^*` (``te_target``) [1].
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed gives the same fit.
    always : bool
        Run the swarm even when WCLS is already stable (a refinement). Default
        False: a stable WCLS result is returned unchanged, as in the paper.

    Returns
    -------
    TFResult
        ``method == "pso-wcls"``; stable whenever the swarm found a stable particle
        (the reflected-pole start always is one).
    """
    t0 = time.perf_counter()
    res = wcls(w, h, n, n_num, weights)
    w, h = _check_frf(w, h)
    nb = res.num.size - 1
    info = {"flipped": 0, "generations": 0, "wcls_te": res.te, "w0": res.info["w0"]}
    if res.stable and not always:
        info["seconds"] = time.perf_counter() - t0
        return TFResult(res.num, res.den, res.te, "pso-wcls", info)
    den0, nflip = _flip_unstable(res.den)
    info["flipped"] = nflip
    w0 = res.info["w0"]
    s = 1j * w / w0
    center = _scale_den(den0, w0)
    lo = np.minimum(center * (1 - spread), center * (1 + spread))
    hi = np.maximum(center * (1 - spread), center * (1 + spread))
    span = hi - lo
    span[span == 0] = 1e-12
    rng = np.random.default_rng(seed)

    def fitness(pos):
        f = np.full(pos.shape[0], np.inf)
        nums = [None] * pos.shape[0]
        comp = np.zeros((pos.shape[0], n, n))
        comp[:, 0, :] = -pos
        if n > 1:
            comp[:, np.arange(1, n), np.arange(0, n - 1)] = 1.0
        roots = np.linalg.eigvals(comp)
        ok = np.all(roots.real < 0, axis=1)
        for k in np.flatnonzero(ok):
            nums[k], f[k] = _num_for_den(s, h, pos[k], nb)
        return f, nums

    x = lo + rng.random((swarm, n)) * (hi - lo)
    x[0] = center  # the reflected-pole denominator is a member of the first swarm
    v = (rng.random((swarm, n)) - 0.5) * span * 0.2
    f, nums = fitness(x)
    pbest, pbest_f, pbest_num = x.copy(), f.copy(), list(nums)
    g = int(np.argmin(pbest_f))
    gbest, gbest_f, gbest_num = pbest[g].copy(), pbest_f[g], pbest_num[g]
    gen = 0
    m_max, m_min = inertia
    while gen < generations and gbest_f > te_target:
        gen += 1
        m = m_max - (m_max - m_min) * (gen - 1) / max(generations - 1, 1)
        r1, r2 = rng.random((swarm, n)), rng.random((swarm, n))
        v = m * v + c1 * r1 * (pbest - x) + c2 * r2 * (gbest - x)
        v = np.clip(v, -span, span)
        x = np.clip(x + v, lo, hi)
        f, nums = fitness(x)
        better = f < pbest_f
        pbest[better], pbest_f[better] = x[better], f[better]
        for k in np.flatnonzero(better):
            pbest_num[k] = nums[k]
        g = int(np.argmin(pbest_f))
        if pbest_f[g] < gbest_f:
            gbest, gbest_f, gbest_num = pbest[g].copy(), pbest_f[g], pbest_num[g]
    info["generations"] = gen
    if not np.isfinite(gbest_f):
        info["seconds"] = time.perf_counter() - t0
        return TFResult(res.num, res.den, res.te, "pso-wcls", info)
    num, den = _unscale(gbest_num, gbest, w0, n)
    te = relative_error(freqresp(num, den, w), h)
    info["seconds"] = time.perf_counter() - t0
    return TFResult(num, den, te, "pso-wcls", info)


def fit_tf(frf: FRF, order: int, method: str = "pso-wcls", n_num: int | None = None,
           **pso_options) -> TFResult:
    """Fit a transfer function to an :class:`FRF` with ``method`` "wcls" or "pso-wcls".

    Parameters
    ----------
    frf : FRF
        The measured response.
    order : int
        Denominator order n.
    method : {"wcls", "pso-wcls"}
    n_num : int, optional
        Numerator order (default ``order``).
    **pso_options
        Passed to :func:`pso_wcls`.
    """
    if method == "wcls":
        return wcls(frf.w, frf.h, order, n_num)
    if method == "pso-wcls":
        return pso_wcls(frf.w, frf.h, order, n_num, **pso_options)
    raise ValueError(f"unknown method {method!r} (wcls, pso-wcls)")


def discretize(num, den, dt: float, method: str = "foh"):
    """Discretize ``num/den`` to state space (``scipy.signal.cont2discrete``).

    Parameters
    ----------
    num, den : array_like
        Continuous coefficients, descending powers of s; proper (``len(num) <= len(den)``).
    dt : float
        Sample period [s].
    method : str
        ``"foh"`` (default: first-order hold, exact for a piecewise-linear input,
        the right choice for sampled smooth signals), ``"zoh"`` (exact for a
        staircase input: a biproper model with a large high-frequency gain then
        responds to every step), or any other method of ``cont2discrete``.

    Returns
    -------
    (Ad, Bd, Cd, Dd) : tuple of ndarray
        Discrete state-space matrices.
    """
    a, b, c, d = signal.tf2ss(num, den)
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, d), dt, method=method)
    return ad, bd, cd, dd


def simulate_tf(num, den, t, u, method: str = "foh") -> np.ndarray:
    """Response of ``num/den`` to ``u`` sampled at ``t``, starting in steady state.

    The initial state is the equilibrium for the constant input ``u[0]``, so a
    record that starts at an offset shows no start-up transient.

    Parameters
    ----------
    num, den : array_like
        Continuous transfer function. If ``I - Ad`` is singular (a pole at s = 0)
        the state starts at zero instead.
    t : array_like
        Uniform sample times [s].
    u : array_like
        Input samples.
    method : str
        Discretization, see :func:`discretize` (default first-order hold).
    """
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    if t.size < 2:
        return np.polyval(num, 0) / np.polyval(den, 0) * u
    dt = float(np.mean(np.diff(t)))
    ad, bd, cd, dd = discretize(num, den, dt, method)
    nx = ad.shape[0]
    if nx == 0:
        return dd[0, 0] * u
    # the same difference equation as the state space, run by lfilter (C speed;
    # dlsim loops in Python), started at the equilibrium for the constant u[0]
    b, a = signal.ss2tf(ad, bd, cd, dd)
    b = np.atleast_1d(np.asarray(b, dtype=float)[0])
    try:
        zi = signal.lfilter_zi(b, a) * u[0]
    except (np.linalg.LinAlgError, ValueError):
        zi = np.zeros(max(len(a), len(b)) - 1)
    if not np.all(np.isfinite(zi)):
        zi = np.zeros_like(zi)
    y, _ = signal.lfilter(b, a, u, zi=zi)
    return np.asarray(y).ravel()
