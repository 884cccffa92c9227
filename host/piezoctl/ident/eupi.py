"""Model kind ``eupi``: extended unparallel Prandtl-Ishlinskii model (CPI + UPI + polynomial).

In normalized units (drive ``v`` and displacement ``z`` both full scale)::

    z = a0 v + sum_i b_i F_{r_i}[v] + sum_ij d_ij F_{rU_i, a_j}[v] + sum_m p_m v**m + p0

exactly :func:`piezoctl.models.eupi.eupi_model`, with ``v`` the drive mapped
from [u_min, u_max] to [-1, 1] and ``z = (y - y_mid) / y_half`` the
displacement mapped from the data's [y_min, y_max] to [-1, 1].

Identification:

1. thresholds on fixed grids: ``r_i = 0.9 i / n_cpi`` (i = 1..n_cpi) and
   ``rU_i = 0.9 i / n_upi``; the CPI's ``r = 0`` operator is ``a0 v``;
2. every play operator of every candidate tilt in ``--eupi-tilts`` is computed
   once; the Gram matrix of all columns is accumulated once;
3. for each subset of ``--eupi-n-tilts`` tilts, the weights are solved by
   bounded least squares (``a0 >= 1e-6``, ``b, d >= 0``, ``p`` free), and the
   subset with the smallest residual wins;
4. ``k_ex`` is the smallest gain that gives the inverse compensator the
   small-gain margin ``--eupi-margin`` (:func:`piezoctl.models.eupi.choose_kex`);
   the margin reached is stored. If no ``k_ex`` reaches it, the model is still
   written, with ``invertible: false`` and the margin at ``k_ex = 0``.

Parameters (``params``): ``u_min``, ``u_max`` [V]; ``y_mid``, ``y_half``
[um]; ``a0``, ``r_cpi``, ``b``, ``r_upi``, ``a_upi``, ``d`` (n_upi x n_tilts),
``p`` (coefficients of v^2..v^Np), ``p0``, ``k_ex`` in the normalized units
of :class:`~piezoctl.models.eupi.EUPIParams`; ``small_gain_margin`` and
``invertible``; ``r_cpi_volts``, ``r_upi_volts`` [V] for reading.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..models import eupi as eupiref
from ..models.play import play_outputs
from .common import Gram, IdentError, check_positive_int, drive_range, normalize

KIND = "eupi"
DESCRIPTION = "extended unparallel Prandtl-Ishlinskii (CPI + UPI + polynomial), constrained least squares"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "to_params", "A0_MIN"]

A0_MIN = 1e-6   # a0 > 0 enforced as a0 >= A0_MIN [output FS / input FS]


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--eupi-``)."""
    parser.add_argument("--eupi-n-cpi", type=int, default=10, metavar="N",
                        help="CPI play operators, thresholds 0.9 i / N (default 10)")
    parser.add_argument("--eupi-n-upi", type=int, default=4, metavar="N",
                        help="UPI thresholds, 0.9 i / N (default 4)")
    parser.add_argument("--eupi-tilts", type=float, nargs="+", default=[0.5, 0.7, 0.85, 1.2, 1.5, 2.0],
                        metavar="A", help="candidate UPI tilts a_j > 0 (default 0.5 0.7 0.85 1.2 1.5 2.0)")
    parser.add_argument("--eupi-n-tilts", type=int, default=2, metavar="K",
                        help="tilts kept: the best K-subset of the candidates (default 2; 0 for no UPI)")
    parser.add_argument("--eupi-poly", type=int, default=3, metavar="NP",
                        help="polynomial degree Np: terms v^2..v^Np (default 3; 1 for none)")
    parser.add_argument("--eupi-margin", type=float, default=0.05, metavar="M",
                        help="small-gain margin required of the inverse [FS/FS] (default 0.05)")


def to_params(p: dict) -> eupiref.EUPIParams:
    """:class:`~piezoctl.models.eupi.EUPIParams` of a parameter dict."""
    return eupiref.EUPIParams(a0=p["a0"], r_cpi=p["r_cpi"], b=p["b"], r_upi=p["r_upi"],
                              a_upi=p["a_upi"], d=np.asarray(p["d"], dtype=np.float64),
                              p=p["p"], p0=p["p0"], k_ex=p.get("k_ex", 0.0))


def fit(recordings, options) -> dict:
    """Fit an EUPI model to recordings.

    Parameters
    ----------
    recordings : sequence of Recording
        Data files (``u`` [V], ``y`` [um]).
    options : mapping
        ``eupi_n_cpi``, ``eupi_n_upi``, ``eupi_tilts``, ``eupi_n_tilts``,
        ``eupi_poly``, ``eupi_margin`` and the common ``u_range``, ``offset``,
        ``max_fit_rows``.

    Returns
    -------
    dict
        Parameters (see the module docstring).
    """
    n_cpi = check_positive_int("--eupi-n-cpi", options.get("eupi_n_cpi", 10), 0)
    n_upi = check_positive_int("--eupi-n-upi", options.get("eupi_n_upi", 4), 0)
    tilts = np.asarray(options.get("eupi_tilts", [0.5, 0.7, 0.85, 1.2, 1.5, 2.0]), dtype=np.float64)
    k = check_positive_int("--eupi-n-tilts", options.get("eupi_n_tilts", 2), 0)
    npoly = check_positive_int("--eupi-poly", options.get("eupi_poly", 3), 1)
    margin = float(options.get("eupi_margin", 0.05))
    if np.any(tilts <= 0) or not np.all(np.isfinite(tilts)):
        raise IdentError("--eupi-tilts: every tilt must be a finite number > 0")
    tilts = np.unique(tilts)
    if n_upi == 0:
        k = 0
    if k > tilts.size:
        raise IdentError(f"--eupi-n-tilts {k}: only {tilts.size} candidate tilts")
    u_min, u_max = drive_range(recordings, options.get("u_range"))
    y_lo = min(float(np.min(r.y)) for r in recordings)
    y_hi = max(float(np.max(r.y)) for r in recordings)
    if not y_hi > y_lo:
        raise IdentError("the displacement y is constant in all data files: nothing to identify")
    y_mid, y_half = 0.5 * (y_lo + y_hi), 0.5 * (y_hi - y_lo)

    r_cpi = 0.9 * np.arange(1, n_cpi + 1) / max(n_cpi, 1)
    r_upi = 0.9 * np.arange(1, n_upi + 1) / max(n_upi, 1)
    ru_all = np.repeat(r_upi, tilts.size)          # all candidate UPI operators, (i, j) row-major
    au_all = np.tile(tilts, r_upi.size)
    X = []
    for r in recordings:
        v = normalize(r.u, u_min, u_max)
        cols = [v[:, None]]
        if n_cpi:
            cols.append(play_outputs(v, r_cpi))
        if k:
            cols.append(play_outputs(v, ru_all, au_all))
        if npoly >= 2:
            cols.append(v[:, None] ** np.arange(2, npoly + 1)[None, :])
        X.append(np.hstack(cols))
    z = [(r.y - y_mid) / y_half for r in recordings]
    gram = Gram(X, z, offset=options.get("offset", "shared"),
                max_rows=options.get("max_fit_rows", 200_000))

    c_upi0 = 1 + n_cpi
    c_poly0 = c_upi0 + (ru_all.size if k else 0)
    poly_cols = np.arange(c_poly0, c_poly0 + max(npoly - 1, 0))
    best = None
    subsets = itertools.combinations(range(tilts.size), k) if k else [()]
    for sub in subsets:
        upi_cols = np.array([c_upi0 + i * tilts.size + j for i in range(n_upi) for j in sub], dtype=int)
        cols = np.concatenate([np.arange(1 + n_cpi), upi_cols, poly_cols]).astype(int)
        lower = np.concatenate([[A0_MIN], np.zeros(n_cpi + upi_cols.size), np.full(poly_cols.size, -np.inf)])
        res = gram.solve(cols=cols, lower=lower)
        if best is None or res.cost < best[0].cost:
            best = (res, sub)
    res, sub = best
    x = res.coef.copy()
    # the solver meets the bounds to rounding; make them exact for EUPIParams' checks
    x[0] = max(x[0], A0_MIN)
    x[1:1 + n_cpi + n_upi * k] = np.maximum(x[1:1 + n_cpi + n_upi * k], 0.0)
    a_upi = tilts[list(sub)] if k else np.zeros(0)
    d = x[1 + n_cpi:1 + n_cpi + n_upi * k].reshape(n_upi, k) if k else np.zeros((0, 0))
    params = {
        "u_min": u_min, "u_max": u_max, "y_mid": y_mid, "y_half": y_half,
        "a0": float(x[0]), "r_cpi": r_cpi, "b": x[1:1 + n_cpi],
        "r_upi": r_upi if k else np.zeros(0), "a_upi": a_upi, "d": d,
        "p": x[1 + n_cpi + n_upi * k:], "p0": res.offset,
    }
    if options.get("offset") == "per-file":
        params["offsets_per_file"] = res.offsets * y_half + y_mid   # [um], displacement units
    base = to_params({**params, "k_ex": 0.0})
    params["margin_at_kex0"] = eupiref.small_gain_margin(base, -1.0, 1.0)
    try:
        kex = eupiref.choose_kex(base, -1.0, 1.0, margin=margin)
        params["k_ex"] = kex
        params["small_gain_margin"] = eupiref.small_gain_margin(eupiref.apply_kex(base, kex), -1.0, 1.0)
        params["invertible"] = True
    except ValueError:
        params["k_ex"] = 0.0
        params["small_gain_margin"] = params["margin_at_kex0"]
        params["invertible"] = False
    half = 0.5 * (u_max - u_min)
    params["r_cpi_volts"] = r_cpi * half
    params["r_upi_volts"] = params["r_upi"] * half
    return params


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V] (``t`` and ``u2`` unused)."""
    try:
        ep = to_params(params)
    except ValueError as exc:
        raise IdentError(f"eupi model: {exc}") from None
    v = normalize(u, params["u_min"], params["u_max"])
    return eupiref.eupi_model(v, ep) * float(params["y_half"]) + float(params["y_mid"])
