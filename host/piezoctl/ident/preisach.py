"""Model kind ``preisach``: the modified Preisach baseline of the cross-coupling paper.

    y(k) = p1 * v(k)**3 + p2 * v(k) + sum_{i=1..n} alpha_i * gamma_i[v](k) + c

with ``v`` the drive normalized to [-1, 1] over the drive range (``u_min`` ->
-1, ``u_max`` -> +1) and ``gamma_i`` classical play operators with thresholds
``r_i = (i - 1) / n`` (normalized units, ``n = 10`` by default), started
relaxed (output 0). All weights are found by ordinary least squares, without
sign constraints, as in the paper.

Note: ``gamma_1`` (``r_1 = 0``) equals ``v`` itself, so ``p2`` and
``alpha_1`` are not separately identifiable; only their sum is. The solver
returns one split of it (Cholesky with a tiny jitter); the output is the same.

Parameters (``params`` of the model file): ``u_min``, ``u_max`` [V] the
normalization; ``n``; ``r`` [normalized] and ``r_volts`` [V] the thresholds;
``p1``, ``p2`` [um]; ``alpha`` [um]; ``offset`` [um]; ``offsets_per_file``
[um] when fitted per file.
"""

from __future__ import annotations

import numpy as np

from ..models.play import play_outputs
from .common import IdentError, check_positive_int, drive_range, normalize, offset_params, solve_linear

KIND = "preisach"
DESCRIPTION = "modified Preisach baseline: cubic + linear + n play operators (least squares)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "features"]


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--preisach-``)."""
    parser.add_argument("--preisach-n", type=int, default=10, metavar="N",
                        help="number of play operators, thresholds (i-1)/N on the normalized input (default 10)")


def features(v: np.ndarray, n: int) -> np.ndarray:
    """Feature columns ``[v**3, v, gamma_1..gamma_n]`` of a normalized input, shape (T, n + 2)."""
    r = np.arange(n) / n
    g = play_outputs(v, r)
    return np.column_stack([v ** 3, v, g])


def fit(recordings, options) -> dict:
    """Fit the modified Preisach model to recordings.

    Parameters
    ----------
    recordings : sequence of Recording
        Data files (``u`` [V], ``y`` [um]).
    options : mapping
        ``preisach_n``, and the common ``u_range``, ``offset``, ``max_fit_rows``.

    Returns
    -------
    dict
        Parameters (see the module docstring).
    """
    n = check_positive_int("--preisach-n", options.get("preisach_n", 10))
    u_min, u_max = drive_range(recordings, options.get("u_range"))
    X = [features(normalize(r.u, u_min, u_max), n) for r in recordings]
    res = solve_linear(X, [r.y for r in recordings], offset=options.get("offset", "shared"),
                       max_rows=options.get("max_fit_rows", 200_000))
    r = np.arange(n) / n
    params = {
        "u_min": u_min, "u_max": u_max, "n": n,
        "r": r, "r_volts": r * 0.5 * (u_max - u_min),
        "p1": float(res.coef[0]), "p2": float(res.coef[1]), "alpha": res.coef[2:],
        **offset_params(res, options),
    }
    return params


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V] (``t`` and ``u2`` unused).

    Raises
    ------
    IdentError
        Parameters inconsistent with each other.
    """
    n = int(params["n"])
    alpha = np.asarray(params["alpha"], dtype=np.float64)
    if alpha.shape != (n,):
        raise IdentError(f"preisach model: {alpha.size} weights alpha for n = {n}")
    v = normalize(u, params["u_min"], params["u_max"])
    X = features(v, n)
    return X @ np.concatenate([[params["p1"], params["p2"]], alpha]) + float(params["offset"])
