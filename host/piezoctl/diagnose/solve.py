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


# A design this many times taller than wide is reduced to its triangular factor before the bounded solve
REDUCE_ROWS_PER_COLUMN = 4


def _bvls():
    """scipy's BVLS iteration itself (the solver ``lsq_linear(method="bvls")`` runs), or None where this scipy has
    it elsewhere (:func:`lstsq_box` then hands the whole design to ``lsq_linear``)."""
    try:
        from scipy.optimize._lsq.bvls import bvls
    except ImportError:   # pragma: no cover - a scipy that moved it
        return None
    return bvls


def lstsq_box(X, y, lo, hi):
    """Least squares with box bounds ``lo <= theta <= hi`` (+-inf: free) on unit-RMS columns.

    Round 22: a tall design (n rows, k columns, n > ``REDUCE_ROWS_PER_COLUMN`` (k + 1)) is reduced first: the QR
    factor ``R`` of ``[X, y]`` gives ``|X t - y|^2 = |R_k t - q|^2 + rho^2`` (``R_k`` its leading k x k block, ``q``
    the first k entries of its last column, ``rho`` its corner), and the bounded solve runs on those k + 1 rows (the
    row ``[0 .. 0, rho]`` keeps the cost, which BVLS' stopping rule compares its change with, the whole design's)
    instead of every row: BVLS solves an unbounded least squares of the rows per step (round 22's profile: 13.8 s of
    the 75 s of held-out s125-023). The same cost, gradient and iterations, with the singular-value cutoff of the
    whole design's (machine precision x n); the solution equal to rounding."""
    from scipy.optimize import lsq_linear
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    A = X / sc
    n, k = A.shape
    lb = np.broadcast_to(np.asarray(lo, float) * sc, (k,)).copy()
    ub = np.broadcast_to(np.asarray(hi, float) * sc, (k,)).copy()
    bvls = _bvls()
    if bvls is None or n <= REDUCE_ROWS_PER_COLUMN * (k + 1):
        sol = lsq_linear(A, y, bounds=(lb, ub), method="bvls", lsq_solver="exact")
        return sol.x / sc
    R = np.linalg.qr(np.column_stack([A, y]), mode="r")
    Ar = np.vstack([R[:k, :k], np.zeros((1, k))])
    br = np.concatenate([R[:k, k], R[k:k + 1, k]])
    x = np.linalg.lstsq(Ar, br, rcond=-1)[0]   # lsq_linear's unbounded start, then its bounded iteration
    if not (np.all(x >= lb) and np.all(x <= ub)):
        x = bvls(Ar, br, x, lb, ub, 1e-10, None, 0, rcond=np.finfo(float).eps * n).x
    return x / sc
