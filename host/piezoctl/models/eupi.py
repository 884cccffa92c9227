"""float64 reference of the extended unparallel Prandtl-Ishlinskii (EUPI) model.

The model maps a drive ``u`` (normalized full scale) to a displacement
(normalized full scale)::

    H[u] = G_CPI[u] + G_UPI[u] + P(u)
    G_CPI[u] = a0 * u + sum_i b_i * F_{r_i, 1}[u]                (classical play)
    G_UPI[u] = sum_i sum_j d_ij * F_{rU_i, a_j}[u]                (unparallel play)
    P(u)     = p0 + sum_{m=2..Np} p_m * u**m                      (Horner)

with ``a0 > 0``, ``a_j > 0``, ``b_i, d_ij >= 0``, thresholds ``>= 0`` and
ascending. The play operators are :func:`piezoctl.models.play.play_outputs`;
every operator starts from output 0.

Inverse compensator (``firmware/core/eupi_inv.c``)::

    u(k) = G1^{-1}[ yr(k) - G2[u](k-1) ]
    G1 = G_CPI + k_ex * u        (inverted analytically: again a PI model)
    G2 = G_UPI + P - k_ex * u

It is a contraction (small-gain) when ``a0 + k_ex > max |dG2/du|`` over the
drive range; :func:`small_gain_margin` evaluates the margin and
:func:`choose_kex` picks ``k_ex``. See ``docs/kernels-pi.md``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .play import play_outputs

__all__ = [
    "EUPIParams", "eupi_model", "poly_eval", "cpi_inverse_params", "eupi_inverse",
    "slope_bounds", "small_gain_margin", "apply_kex", "choose_kex",
]


def _vec(x) -> np.ndarray:
    return np.atleast_1d(np.asarray(x, dtype=np.float64)).copy()


@dataclass(frozen=True)
class EUPIParams:
    """Parameters of an EUPI model (all in normalized full-scale units).

    Attributes
    ----------
    a0 : float
        Linear gain of the CPI part, ``> 0`` [output/input].
    r_cpi : ndarray, shape (n,)
        CPI thresholds, ``>= 0``, ascending [input FS].
    b : ndarray, shape (n,)
        CPI weights, ``>= 0`` [output/input].
    r_upi : ndarray, shape (nr,)
        UPI thresholds, ``>= 0``, ascending [input FS].
    a_upi : ndarray, shape (na,)
        UPI upper-branch slopes, ``> 0`` [dimensionless].
    d : ndarray, shape (nr, na)
        UPI weights, ``>= 0``; ``d[i, j]`` weighs ``F_{r_upi[i], a_upi[j]}``
        [output/input].
    p : ndarray, shape (Np - 1,)
        Polynomial coefficients of ``u**2 .. u**Np`` [output/input**m].
    p0 : float
        Constant offset [output FS].
    k_ex : float
        Gain moved from ``G_UPI + P`` to ``G_CPI`` for the inverse
        compensator only; the model ``H`` does not depend on it.
    """

    a0: float
    r_cpi: np.ndarray
    b: np.ndarray
    r_upi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    a_upi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    d: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    p: np.ndarray = field(default_factory=lambda: np.zeros(0))
    p0: float = 0.0
    k_ex: float = 0.0

    def __post_init__(self):
        s = object.__setattr__
        s(self, "a0", float(self.a0))
        s(self, "p0", float(self.p0))
        s(self, "k_ex", float(self.k_ex))
        for name in ("r_cpi", "b", "r_upi", "a_upi", "p"):
            s(self, name, _vec(getattr(self, name)) if np.size(getattr(self, name)) else np.zeros(0))
        d = np.asarray(self.d, dtype=np.float64).reshape(self.r_upi.size, self.a_upi.size).copy()
        s(self, "d", d)
        if not self.a0 > 0:
            raise ValueError("a0 must be > 0")
        if self.r_cpi.shape != self.b.shape:
            raise ValueError("r_cpi and b must have the same length")
        for name in ("r_cpi", "r_upi"):
            r = getattr(self, name)
            if np.any(r < 0) or np.any(np.diff(r) < 0):
                raise ValueError(f"{name} must be >= 0 and ascending")
        if np.any(self.a_upi <= 0):
            raise ValueError("a_upi must be > 0")
        if np.any(self.b < 0) or np.any(self.d < 0):
            raise ValueError("weights b and d must be >= 0")
        for name in ("a0", "r_cpi", "b", "r_upi", "a_upi", "d", "p", "p0", "k_ex"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be finite")

    @property
    def n_upi(self) -> int:
        """Number of UPI operators, ``len(r_upi) * len(a_upi)``."""
        return self.d.size


def poly_eval(u, p0: float, p) -> np.ndarray:
    """``P(u) = p0 + sum_m p[m-2] * u**m`` for ``m = 2..Np``, by Horner.

    Parameters
    ----------
    u : array_like
        Input [FS].
    p0 : float
        Constant term [FS].
    p : array_like, shape (Np - 1,)
        Coefficients of ``u**2 .. u**Np``.
    """
    u = np.asarray(u, dtype=np.float64)
    p = np.atleast_1d(np.asarray(p, dtype=np.float64))
    if p.size == 0:
        return np.full_like(u, p0)
    h = np.full_like(u, p[-1])
    for c in p[-2::-1]:
        h = h * u + c
    return h * u * u + p0


def _poly_deriv(p) -> np.ndarray:
    """Coefficients (ascending powers ``u**0 ..``) of ``P'(u)``."""
    p = np.atleast_1d(np.asarray(p, dtype=np.float64))
    # P' = sum_m m p_m u^(m-1), m = 2..Np  ->  powers 1..Np-1
    return np.concatenate([[0.0], (np.arange(2, p.size + 2) * p)]) if p.size else np.zeros(1)


def _upi_bank(params: EUPIParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-operator threshold, slope and weight of the UPI grid, row-major (i, j)."""
    nr, na = params.r_upi.size, params.a_upi.size
    return np.repeat(params.r_upi, na), np.tile(params.a_upi, nr), params.d.ravel()


def eupi_model(u, params: EUPIParams) -> np.ndarray:
    """Output of the EUPI model for the input sequence ``u``.

    Parameters
    ----------
    u : array_like, shape (T,)
        Drive [FS].
    params : EUPIParams

    Returns
    -------
    ndarray, shape (T,)
        ``H[u]`` [output FS], every play operator starting from 0.
    """
    u = np.asarray(u, dtype=np.float64)
    y = params.a0 * u + poly_eval(u, params.p0, params.p)
    if params.r_cpi.size:
        y = y + play_outputs(u, params.r_cpi) @ params.b
    if params.n_upi:
        r, a, w = _upi_bank(params)
        y = y + play_outputs(u, r, a) @ w
    return y


def cpi_inverse_params(a0: float, r, b) -> tuple[float, np.ndarray, np.ndarray]:
    """Analytic inverse of a classical PI model ``a0 u + sum_i b_i F_{r_i}[u]``.

    The inverse is again a PI model ``a0' v + sum_i b'_i F_{r'_i}[v]`` (all
    play operators starting from 0 on both sides). With the thresholds sorted,
    ``A_0 = a0`` and ``A_i = a0 + sum_{j<=i} b_j`` (slope of the initial
    loading curve above ``r_i``)::

        r'_i = a0 r_i + sum_{j<i} b_j (r_i - r_j)     (loading curve at r_i)
        a0'  = 1 / a0
        b'_i = 1 / A_i - 1 / A_{i-1}                  (<= 0)

    Parameters
    ----------
    a0 : float
        Linear gain, ``> 0`` [output/input].
    r : array_like, shape (n,)
        Thresholds, ``>= 0`` [input FS].
    b : array_like, shape (n,)
        Weights, ``>= 0`` [output/input].

    Returns
    -------
    a0_inv : float
        [input/output].
    r_inv : ndarray, shape (n,)
        Ascending thresholds of the inverse [output FS].
    b_inv : ndarray, shape (n,)
        Weights of the inverse, non-positive [input/output], in the order of
        the sorted thresholds.

    Examples
    --------
    >>> a0i, ri, bi = cpi_inverse_params(1.0, [0.0, 0.5], [1.0, 2.0])
    >>> a0i, ri.tolist(), bi.tolist()
    (1.0, [0.0, 1.0], [-0.5, -0.25])
    """
    r = _vec(r)
    b = _vec(b)
    if r.shape != b.shape:
        raise ValueError("r and b must have the same length")
    if not a0 > 0 or np.any(b < 0) or np.any(r < 0):
        raise ValueError("need a0 > 0, b >= 0, r >= 0")
    order = np.argsort(r, kind="stable")
    r, b = r[order], b[order]
    slopes = a0 + np.concatenate([[0.0], np.cumsum(b)])         # A_0 .. A_n
    # r'_i = a0 r_i + sum_{j<i} b_j (r_i - r_j)
    r_inv = a0 * r + np.array([np.sum(b[:i] * (r[i] - r[:i])) for i in range(r.size)])
    b_inv = 1.0 / slopes[1:] - 1.0 / slopes[:-1]
    return 1.0 / a0, r_inv, b_inv


def eupi_inverse(yr, params: EUPIParams, u_range: tuple[float, float] | None = (-1.0, 1.0)):
    """float64 inverse compensator: drive ``u`` for a desired displacement ``yr``.

    ``u(k) = G1^{-1}[v](k)``, ``v(k) = yr(k) - G2[u](k-1)``, with
    ``G1 = G_CPI + k_ex u`` inverted by :func:`cpi_inverse_params` and
    ``G2 = G_UPI + P - k_ex u``; ``G2(-1) = p0`` (all operators at 0,
    ``u(-1) = 0``). The drive is clamped to ``u_range`` before it enters
    ``G2`` (the firmware clamps to q15 the same way); the inverse CPI
    operators keep the unclamped ``v``.

    Parameters
    ----------
    yr : array_like, shape (T,)
        Desired displacement [output FS].
    params : EUPIParams
        Model, with ``k_ex`` (see :func:`choose_kex`).
    u_range : (float, float) or None
        Drive limits [FS]; ``None`` disables the clamp.

    Returns
    -------
    ndarray, shape (T,)
        Drive [FS].
    """
    yr = np.asarray(yr, dtype=np.float64)
    g1 = params.a0 + params.k_ex
    a0i, ri, bi = cpi_inverse_params(g1, params.r_cpi, params.b)
    ru, au, wu = _upi_bank(params)
    fi = np.zeros(ri.size)
    fu = np.zeros(ru.size)
    lo_u, hi_u = (-np.inf, np.inf) if u_range is None else u_range
    p0, p, kex = params.p0, params.p, params.k_ex
    g2 = p0
    out = np.empty(yr.size)
    for k in range(yr.size):
        v = yr[k] - g2
        fi = np.maximum(v - ri, np.minimum(v + ri, fi))
        u = a0i * v + float(fi @ bi)
        u = min(hi_u, max(lo_u, u))
        out[k] = u
        fu = np.maximum(u - ru, np.minimum(au * (u + ru), fu))
        g2 = float(fu @ wu) + float(poly_eval(u, p0, p)) - kex * u
    return out


def slope_bounds(params: EUPIParams, u_min: float = -1.0, u_max: float = 1.0):
    """Range ``[lo, hi]`` of the incremental slope of ``G2 = G_UPI + P - k_ex u``.

    Each UPI operator moves along its lower branch (slope 1) while ``u``
    rises, along its upper branch (slope ``a_j``) while ``u`` falls, or
    stays (slope 0); across any step ``|dF| <= max(1, a_j) |du|`` with
    ``dF/du >= 0``. With ``d_ij >= 0`` the play part's difference quotient
    therefore lies in ``[0, S]``, ``S = sum_ij d_ij max(1, a_j)``, whichever
    operators are active (no assumption on the history). The polynomial's
    quotient is ``P'(xi)`` for some ``xi`` in the range (mean value
    theorem); its extremes are taken at the ends and at the real roots of
    ``P''`` inside the range.

    Returns
    -------
    lo, hi : float
        ``lo = min P' - k_ex``, ``hi = max P' + S - k_ex`` [output/input].
    """
    if not u_min < u_max:
        raise ValueError("need u_min < u_max")
    dp = _poly_deriv(params.p)                          # ascending powers
    cand = [u_min, u_max]
    if dp.size > 2:
        ddp = np.polynomial.polynomial.polyder(dp)
        for z in np.polynomial.polynomial.polyroots(ddp) if np.any(ddp) else []:
            if abs(z.imag) < 1e-12 and u_min < z.real < u_max:
                cand.append(float(z.real))
    vals = np.polynomial.polynomial.polyval(np.array(cand), dp)
    s_play = float(np.sum(params.d * np.maximum(1.0, params.a_upi)[None, :]))
    return float(vals.min()) - params.k_ex, float(vals.max()) + s_play - params.k_ex


def small_gain_margin(params: EUPIParams, u_min: float = -1.0, u_max: float = 1.0) -> float:
    """Small-gain margin of the inverse compensator over the drive range.

    ``margin = (a0 + k_ex) - max |dG2/du|`` with the slope range of
    :func:`slope_bounds`; with ``k_ex = 0`` it is ``a0 - max |d(G_UPI + P)/du|``.
    The compensator is a contraction, hence stable, when the margin is
    ``> 0``; the contraction factor is ``1 - margin / (a0 + k_ex)``.

    Parameters
    ----------
    params : EUPIParams
    u_min, u_max : float
        Drive range [FS].

    Returns
    -------
    float
        Margin [output/input].
    """
    lo, hi = slope_bounds(params, u_min, u_max)
    return params.a0 + params.k_ex - max(abs(lo), abs(hi))


def apply_kex(params: EUPIParams, k_ex: float) -> EUPIParams:
    """Copy of ``params`` with ``k_ex`` gain moved from ``G_UPI + P`` to ``G_CPI``.

    The model is unchanged; only the inverse's split is:
    ``G1 = G_CPI + k_ex u``, ``G2 = G_UPI + P - k_ex u``.
    """
    if not params.a0 + k_ex > 0:
        raise ValueError("a0 + k_ex must be > 0")
    return dataclasses.replace(params, k_ex=float(k_ex))


def choose_kex(params: EUPIParams, u_min: float = -1.0, u_max: float = 1.0,
               margin: float = 0.05) -> float:
    """Smallest ``k_ex >= 0`` whose small-gain margin is at least ``margin``.

    With ``[lo, hi]`` the slope range of ``G_UPI + P`` (:func:`slope_bounds`
    at ``k_ex = 0``), the margin is ``a0 + k - max(|lo - k|, |hi - k|)``: it
    grows as ``a0 + 2 k - hi`` up to ``k = (lo + hi) / 2`` and stays at
    ``a0 + lo`` beyond. The rule is therefore::

        k_ex = max(0, (margin + hi - a0) / 2)

    and it fails when even the plateau ``a0 + lo`` is below ``margin``.
    The smallest sufficient ``k_ex`` is chosen, not the one with the
    smallest contraction factor (``(lo + hi) / 2``): the compensator's
    one-step tracking error is ``G2(k) - G2(k-1)``, and the ``-k_ex u`` term
    in ``G2`` makes it grow with ``k_ex``.

    Parameters
    ----------
    params : EUPIParams
        Model; its own ``k_ex`` is ignored.
    u_min, u_max : float
        Drive range [FS].
    margin : float
        Required :func:`small_gain_margin` [output/input], ``> 0`` for a
        contraction.

    Returns
    -------
    float
        ``k_ex``; pass it to :func:`apply_kex`.

    Raises
    ------
    ValueError
        If no ``k_ex >= 0`` reaches ``margin`` (``a0 + min P' < margin``: the
        model is not monotone enough to be inverted this way).
    """
    base = dataclasses.replace(params, k_ex=0.0)
    lo, hi = slope_bounds(base, u_min, u_max)
    k = max(0.0, 0.5 * (margin + hi - params.a0))
    got = small_gain_margin(dataclasses.replace(params, k_ex=k), u_min, u_max)
    if got < margin - 1e-12:
        raise ValueError(f"no k_ex >= 0 reaches small-gain margin {margin:g}: "
                         f"a0 + min P' = {params.a0 + lo:g}")
    return k
