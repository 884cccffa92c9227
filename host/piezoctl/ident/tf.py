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

Output-error refinement (``refine=True``, the default of :func:`pso_wcls`)
    WCLS minimizes the *equation* error :math:`|A(j\\omega_i) D_i - A(j\\omega_i) H_i|`
    weighted by :math:`1/|H_i|^2`: the relative output error multiplied by
    :math:`|A(j\\omega_i)|`. That factor grows as :math:`\\omega^n` above the poles,
    so noise at the high end of the band drags the fit (the Levy bias), and the
    fitted denominator can be unstable. The refinement removes the factor: it
    minimizes the relative *output* error

    .. math::

        \\sum_i \\frac{|N(j\\omega_i)/A(j\\omega_i) - H_i|^2}{|H_i|^2}

    (the maximum-likelihood criterion for complex multiplicative noise) by
    Levenberg-Marquardt-type trust-region least squares
    (``scipy.optimize.least_squares``, ``trf``), started from the stable PSO-WCLS
    model. Only the denominator is a nonlinear unknown: for a given :math:`A` the
    numerator is the linear least-squares solution (variable projection). The
    denominator is a product of sections :math:`s'^2 + 2\\zeta\\omega_n s' + \\omega_n^2`
    (and one :math:`s' + \\omega_n` for an odd order) in the scaled frequency, with
    :math:`\\omega_n = e^{\\theta_1}`, :math:`\\zeta = e^{\\theta_2} \\ge 10^{-6}`: every
    such polynomial is stable (:math:`\\zeta > 1` is a pair of real poles) and every
    stable one is such a product, so the search never leaves the stable models.

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
    "refine_output_error",
    "sanathanan_koerner",
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
        ``"wcls"``, ``"pso-wcls"`` or ``"wcls-sk"``.
    info : dict
        Details: ``flipped`` (number of reflected poles), ``generations`` (PSO
        generations run), ``wcls_te``, ``w0`` [rad/s], ``seconds``; from
        :func:`pso_wcls` also ``refined``, ``pso_te``, ``refine_evaluations``,
        ``refine_status``.
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


def _projected_numerator(s, h, a, nb):
    """Least-squares numerator (scaled, descending) for denominator values ``a`` at ``s``.

    Minimizes the relative output error :math:`|N(s_i)/a_i - H_i| / |H_i|`, linear in
    the numerator. Returns the numerator and the complex relative errors.
    """
    ah = np.abs(h)
    r = np.column_stack([s ** k for k in range(nb, -1, -1)]) / (a * ah)[:, None]
    tgt = h / ah
    xr = np.vstack([r.real, r.imag])
    cn = np.linalg.norm(xr, axis=0)
    cn[cn == 0] = 1.0
    b = np.linalg.lstsq(xr / cn, np.concatenate([tgt.real, tgt.imag]), rcond=None)[0] / cn
    return b, (np.polyval(b, s) / a - h) / ah


def _num_for_den(s, h, den_low_scaled, nb):
    """Least-squares numerator (scaled) for a fixed scaled denominator; relative error Te."""
    n = den_low_scaled.size
    a = s ** n + sum(den_low_scaled[i] * s ** (n - 1 - i) for i in range(n))
    b, e = _projected_numerator(s, h, a, nb)
    return b, float(np.mean(np.abs(e)))


ZETA_MIN = 1e-6
"""Smallest damping ratio of a section in the refinement [1] (keeps it strictly stable)."""
ZETA_MAX = 10.0
"""Largest damping ratio of a section in the refinement [1]: a pair of real poles
at most about 4 ZETA_MAX^2 = 400 apart."""
POLE_RANGE = 10.0
"""Natural frequencies in the refinement lie within ``[min(w) / POLE_RANGE,
POLE_RANGE max(w)]`` [1]."""


def _sections_from_den(den_scaled) -> list[np.ndarray]:
    """Stable monic polynomial (scaled, descending) -> section parameters, one per start.

    Complex pairs and pairs of real roots (adjacent in magnitude) become
    :math:`(\\ln\\omega_n, \\ln\\zeta)`; with an odd number of real roots one is
    left over as a first-order section :math:`\\ln\\omega_n`, last. Which one is
    a guess, so one parameter vector is returned per choice (one vector when
    there is no choice). The start is stable, but a root the reflection put just
    left of the axis may come back from ``np.roots`` on it: real parts are taken
    as :math:`-|\\mathrm{Re}\\,p|` and the damping clamped to ``ZETA_MIN``.
    """
    p = np.roots(den_scaled)
    p = -np.abs(p.real) + 1j * p.imag
    tiny = 1e-12
    th_pairs = []
    for z in sorted((z for z in p if z.imag > 0), key=abs):
        wn = max(abs(z), tiny)
        th_pairs += [np.log(wn), np.log(max(-z.real / wn, ZETA_MIN))]
    real = sorted((float(z.real) for z in p if z.imag == 0), key=abs)
    leftovers = range(len(real)) if len(real) % 2 else [None]
    out = []
    for k in leftovers:
        rest = [r for i, r in enumerate(real) if i != k]
        th = list(th_pairs)
        for r1, r2 in zip(rest[0::2], rest[1::2]):
            wn = max(np.sqrt(r1 * r2), tiny)
            th += [np.log(wn), np.log(max(-(r1 + r2) / (2 * wn), ZETA_MIN))]
        if k is not None:
            th.append(np.log(max(-real[k], tiny)))
        out.append(np.array(th))
    return out


def _den_from_sections(th) -> np.ndarray:
    """Section parameters -> monic polynomial (scaled, descending); inverse of :func:`_sections_from_den`."""
    d = np.array([1.0])
    for i in range(0, th.size - 1, 2):
        wn, z = np.exp(th[i]), np.exp(th[i + 1])
        d = np.polymul(d, [1.0, 2.0 * z * wn, wn * wn])
    if th.size % 2:
        d = np.polymul(d, [1.0, np.exp(th[-1])])
    return d


def refine_output_error(w, h, start: TFResult, n_num: int | None = None) -> TFResult:
    """Minimize the relative output error from a stable start; the result is stable.

    The denominator is searched as stable sections (module docstring) with
    :math:`10^{-6} \\le \\zeta \\le` ``ZETA_MAX`` and natural frequencies within a
    decade of the data, ``POLE_RANGE``: from ``min(w) / 10`` to ``10 max(w)``. A
    pole further out is not determined by the data (without the bound a real pole
    can run off towards infinity, 4.5e10 Hz on the SIL stage's chirp).

    Parameters
    ----------
    w, h
        As for :func:`wcls`: angular frequencies [rad/s] and the measured response.
    start : TFResult
        A stable model of the wanted order (e.g. from :func:`pso_wcls` with
        ``refine=False``); its ``info["w0"]`` [rad/s] is the frequency scale
        (default ``max(w)``).
    n_num : int, optional
        Numerator order (default: the start's).

    Returns
    -------
    TFResult
        ``method`` copied from the start; ``info``: ``refine_evaluations`` (residual
        evaluations), ``refine_status`` (``least_squares`` status of the kept
        solution, 0 when the start was kept), ``start_te``. Its sum of squared
        relative errors is never above the start's: if the search ends higher
        (a start outside the bounds), the start is returned.
    """
    w, h = _check_frf(w, h)
    n = start.den.size - 1
    nb = start.num.size - 1 if n_num is None else int(n_num)
    w0 = float(start.info.get("w0", w.max()))
    s = 1j * w / w0
    den_s = np.concatenate(([1.0], _scale_den(start.den, w0)))
    zeta = np.zeros(n, dtype=bool)  # n parameters: (ln wn, ln zeta) per section, ln wn for a first-order one
    zeta[1:2 * (n // 2):2] = True
    lo = np.where(zeta, np.log(ZETA_MIN), np.log(w.min() / w0 / POLE_RANGE))
    hi = np.where(zeta, np.log(ZETA_MAX), np.log(w.max() / w0 * POLE_RANGE))

    def residual(x):
        a = np.polyval(_den_from_sections(x), s)
        e = _projected_numerator(s, h, a, nb)[1]
        return np.concatenate([e.real, e.imag])

    from scipy.optimize import least_squares  # scipy.optimize only here

    e0 = (freqresp(start.num, start.den, w) - h) / np.abs(h)
    cost0 = 0.5 * float(np.sum(np.abs(e0) ** 2))
    x, cost, nfev, status = None, np.inf, 0, 0
    for start_x in _sections_from_den(den_s):
        sol = least_squares(residual, np.clip(start_x, lo, hi), bounds=(lo, hi), method="trf")
        nfev += int(sol.nfev)
        if sol.cost < cost:
            x, cost, status = sol.x, float(sol.cost), int(sol.status)
    info = dict(start.info)
    info.update({"refine_evaluations": nfev, "refine_status": status, "start_te": float(start.te)})
    if not cost <= cost0:  # never worse than the start
        info["refine_status"] = 0
        return TFResult(start.num, start.den, start.te, start.method, info)
    d = _den_from_sections(x)
    b = _projected_numerator(s, h, np.polyval(d, s), nb)[0]
    num, den = _unscale(b, d[1:], w0, n)
    te = relative_error(freqresp(num, den, w), h)
    return TFResult(num, den, te, start.method, info)


def sanathanan_koerner(w, h, n: int, n_num: int | None = None, iterations: int = 10) -> TFResult:
    """WCLS iterated with the Sanathanan-Koerner weights :math:`1/(|H_i|^2 |A_{k-1}(j\\omega_i)|^2)`.

    Each iteration divides the equation error by the previous denominator, which
    removes the :math:`|A|` factor of WCLS at convergence; nothing keeps the poles
    stable. For comparison in ``tools/bench-tf`` (``docs/dynamics.md``).

    Parameters
    ----------
    w, h, n, n_num
        As for :func:`wcls`.
    iterations : int
        Reweighted WCLS solves after the first one.

    Returns
    -------
    TFResult
        ``method == "wcls-sk"``; may be unstable.
    """
    t0 = time.perf_counter()
    res = wcls(w, h, n, n_num)
    w, h = _check_frf(w, h)
    w0 = res.info["w0"]
    for _ in range(int(iterations)):
        a = np.polyval(np.concatenate(([1.0], _scale_den(res.den, w0))), 1j * w / w0)
        res = wcls(w, h, n, n_num, weights=1.0 / (np.abs(h) ** 2 * np.abs(a) ** 2))
    res.method = "wcls-sk"
    res.info["seconds"] = time.perf_counter() - t0
    return res


def pso_wcls(w, h, n: int, n_num: int | None = None, weights=None, *, swarm: int = 100,
             generations: int = 20, spread: float = 0.5, inertia=(0.9, 0.4),
             c1: float = 2.0, c2: float = 2.0, te_target: float = 1e-3, seed: int = 0,
             always: bool = False, refine: bool = True) -> TFResult:
    """WCLS, then (if unstable) a particle-swarm search for a stable denominator,
    then (``refine``) the output-error refinement from that stable model.

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
        False: a stable WCLS result goes on unchanged, as in the paper.
    refine : bool
        Refine the stable model by :func:`refine_output_error` (default True).
        False returns the paper's PSO-WCLS result alone (for comparison).

    Returns
    -------
    TFResult
        ``method == "pso-wcls"``, always stable (checked: an unstable result
        raises ``RuntimeError``, a bug). ``info``: ``flipped``, ``generations``,
        ``wcls_te``, ``w0``, ``refined``, ``pso_te`` (Te before the refinement),
        ``refine_evaluations``, ``seconds``.
    """
    t0 = time.perf_counter()
    res = _paper_pso_wcls(w, h, n, n_num, weights, swarm=swarm, generations=generations,
                          spread=spread, inertia=inertia, c1=c1, c2=c2, te_target=te_target,
                          seed=seed, always=always)
    res.info["refined"] = bool(refine)
    res.info["pso_te"] = res.te
    if refine:
        res = refine_output_error(w, h, res, n_num)
        del res.info["start_te"]
    res.info["seconds"] = time.perf_counter() - t0
    if not res.stable:
        raise RuntimeError(f"pso-wcls returned an unstable model (poles {res.poles}): a bug")
    return res


def _paper_pso_wcls(w, h, n, n_num, weights, *, swarm, generations, spread, inertia, c1, c2,
                    te_target, seed, always) -> TFResult:
    """The paper's PSO-WCLS (options as :func:`pso_wcls`): stable WCLS, or the swarm's best.

    When the swarm finds no stable particle (it starts from the reflected-pole
    denominator, which is stable, so only through rounding) the reflected-pole
    model is returned.
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
        gbest = center
        gbest_num = _num_for_den(s, h, center, nb)[0]
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
        Passed to :func:`pso_wcls` (``seed``, ``always``, ``refine``, ...).
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
