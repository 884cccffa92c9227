"""Small least-squares solves shared by the selection (select.py) and the slow-term signatures
(slow_signature.py); a module of its own so that the two do not import each other."""

from __future__ import annotations

import numpy as np


def train_rows(train, rows):
    """Indices of the training rows, strided to at most ``rows`` of them."""
    idx = np.flatnonzero(train)
    if idx.size > rows:
        idx = idx[:: int(np.ceil(idx.size / rows))]
    return idx


def lstsq_box(X, y, lo, hi):
    """Least squares with box bounds ``lo <= theta <= hi`` (+-inf: free) on unit-RMS columns."""
    from scipy.optimize import lsq_linear
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    sol = lsq_linear(X / sc, y, bounds=(np.asarray(lo, float) * sc, np.asarray(hi, float) * sc), method="bvls",
                     lsq_solver="exact")
    return sol.x / sc


def lstsq_box_below(X, y, lo, hi, sse_max: float):
    """:func:`lstsq_box`'s coefficients (the same floats), or None when its sum of squared residuals cannot be
    below ``sse_max`` [units of y squared].

    ``scipy.optimize.lsq_linear`` (BVLS) first solves without bounds and returns that solution when it is within
    them; otherwise its BVLS iterations solve the free columns' least squares again, at least once more. The
    unbounded minimum is a lower bound of the bounded one: when the unbounded solution's sum of squares exceeds
    ``sse_max`` the iterations cannot find a fit below it, and they are skipped. The caller states the margin
    for round-off in ``sse_max`` (the unbounded solution's computed sum of squares exceeds the exact minimum by
    a relative 1e-12 or less on these designs; :data:`SSE_MARGIN`). Otherwise the same steps as ``lsq_linear``
    with ``method="bvls", lsq_solver="exact"``: its unbounded ``lstsq`` (``rcond=-1``), its feasibility test
    and its BVLS routine on the same arrays (``tests/host/test_diagnose_speed_round24.py`` compares them bit
    for bit)."""
    from scipy.optimize._lsq.bvls import bvls
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    A = X / sc
    lb = np.asarray(lo, float) * sc
    ub = np.asarray(hi, float) * sc
    if lb.ndim == 0:
        lb = np.resize(lb, A.shape[1])
    if ub.ndim == 0:
        ub = np.resize(ub, A.shape[1])
    y = np.atleast_1d(y)
    x = np.linalg.lstsq(A, y, rcond=-1)[0]
    if np.all((x >= lb) & (x <= ub)):
        return x / sc
    r = A @ x - y
    if float(np.dot(r, r)) > sse_max:
        return None
    return bvls(A, y, x, lb, ub, 1e-10, None, 0).x / sc


# [1] relative round-off allowed for when a sum of squares is compared with lstsq_box_below's bound: far above the
# computed unbounded minimum's error (a relative 1e-12 or less). A larger margin only skips fewer fits
SSE_MARGIN = 1e-6
