"""Model kind ``kp``: Krasnosel'skii-Pokrovskii model fitted by least squares.

    y(k) = sum_j w_j psi_j[v](k) + c1 * v(k) + c

``v`` is the drive normalized to [-1, 1] over the drive range (``u_min`` ->
-1, ``u_max`` -> +1), ``psi_j`` are the KP operators of the float reference
:func:`piezoctl.models.kp.kp_outputs` on the grid ``kp_grid(L, -1, 1, s)``
(``N = L (L + 1) / 2`` cells, outputs in [0, 1]), started in the reference's
reset state (all operators 0, previous input at the bottom of the plane).
The density ``w`` is a weight per cell: a Preisach density is non-negative,
so ``w >= 0`` by default (bounded least squares); the optional linear term
``c1 >= 0`` is the reversible (anhysteretic) part; the offset ``c`` is free.

Parameters (``params`` of the model file): ``u_min``, ``u_max`` [V];
``L``, ``nmin``, ``nmax``, ``s`` [normalized] the grid; ``w`` [um per unit
operator output], ``N`` values in the reference's cell order; ``linear`` [um
per normalized drive] (0 when not fitted); ``offset`` [um];
``offsets_per_file`` [um] with ``--offset per-file``.
"""

from __future__ import annotations

import numpy as np

from ..models import kp as kpref
from .common import IdentError, check_positive_int, drive_range, normalize, offset_params, solve_linear

KIND = "kp"
DESCRIPTION = "Krasnosel'skii-Pokrovskii density on an L-level grid (non-negative least squares)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "grid_of", "operator_outputs"]


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--kp-``)."""
    parser.add_argument("--kp-levels", type=int, default=10, metavar="L",
                        help="grid intervals per axis: L (L + 1) / 2 operators (default 10)")
    parser.add_argument("--kp-ridge", type=float, default=None, metavar="S",
                        help="ridge width s on the normalized input (default 2 / (L - 1))")
    parser.add_argument("--kp-linear", choices=("on", "off"), default="on",
                        help="also fit a linear term c1 * v, c1 >= 0 (default on)")
    parser.add_argument("--kp-signed", action="store_true",
                        help="allow negative density weights (default: w >= 0)")


def grid_of(params: dict) -> kpref.KPGrid:
    """The KP grid of a ``kp`` (or ``rkp``) parameter set."""
    return kpref.kp_grid(int(params["L"]), float(params["nmin"]), float(params["nmax"]),
                         float(params["s"]))


def operator_outputs(v: np.ndarray, grid: kpref.KPGrid) -> np.ndarray:
    """Every KP operator's output for normalized input ``v`` (reset state), shape (T, N)."""
    return kpref.kp_outputs(v, grid)


def fit(recordings, options) -> dict:
    """Fit a KP model to recordings.

    Parameters
    ----------
    recordings : sequence of Recording
        Data files (``u`` [V], ``y`` [um]).
    options : mapping
        ``kp_levels``, ``kp_ridge``, ``kp_linear``, ``kp_signed`` and the
        common ``u_range``, ``offset``, ``max_fit_rows``.

    Returns
    -------
    dict
        Parameters (see the module docstring).
    """
    L = check_positive_int("--kp-levels", options.get("kp_levels", 10))
    s = options.get("kp_ridge")
    if s is not None and not s > 0:
        raise IdentError(f"--kp-ridge {s:g}: must be > 0")
    grid = kpref.kp_grid(L, -1.0, 1.0, s)
    linear = options.get("kp_linear", "on") == "on"
    u_min, u_max = drive_range(recordings, options.get("u_range"))
    X = []
    for r in recordings:
        v = normalize(r.u, u_min, u_max)
        psi = operator_outputs(v, grid)
        X.append(np.column_stack([psi, v]) if linear else psi)
    lower = -np.inf if options.get("kp_signed", False) else 0.0
    res = solve_linear(X, [r.y for r in recordings], lower=lower,
                       offset=options.get("offset", "shared"),
                       max_rows=options.get("max_fit_rows", 200_000))
    params = {
        "u_min": u_min, "u_max": u_max,
        "L": grid.L, "nmin": grid.nmin, "nmax": grid.nmax, "s": grid.s, "N": grid.N,
        "w": res.coef[:grid.N],
        "linear": float(res.coef[grid.N]) if linear else 0.0,
        **offset_params(res, options),
    }
    return params


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V] (``t`` and ``u2`` unused)."""
    grid = grid_of(params)
    w = np.asarray(params["w"], dtype=np.float64)
    if w.shape != (grid.N,):
        raise IdentError(f"kp model: {w.size} weights for a grid of {grid.N} operators")
    v = normalize(u, params["u_min"], params["u_max"])
    return kpref.kp_model(v, grid, w) + float(params.get("linear", 0.0)) * v + float(params["offset"])
