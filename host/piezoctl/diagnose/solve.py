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


def lstsq_box(X, y, lo, hi, floor=None):
    """Least squares with box bounds ``lo <= theta <= hi`` (+-inf: free) on unit-RMS columns.

    ``floor`` (round 26): a sum of squared residuals [y's unit^2]; None is returned instead of the bounded fit
    when the *unbounded* fit is outside the box and leaves at least ``floor`` (the bounded fit leaves at least
    as much: a caller ranking fits by their error does not need it). The unbounded fit is the first step of
    ``lsq_linear`` (the same call on the same scaled design); inside the box it is ``lsq_linear``'s answer, taken
    as it is; outside, ``lsq_linear`` is called as without ``floor`` (its first step again)."""
    from scipy.optimize import lsq_linear
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    A = X / sc
    lo_s, hi_s = np.asarray(lo, float) * sc, np.asarray(hi, float) * sc
    if floor is not None:
        x = np.linalg.lstsq(A, y, rcond=-1)[0]
        if np.all((x >= lo_s) & (x <= hi_s)):
            return x / sc
        r = A @ x - y
        if float(r @ r) >= floor:
            return None
    sol = lsq_linear(A, y, bounds=(lo_s, hi_s), method="bvls", lsq_solver="exact")
    return sol.x / sc
