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
