"""The sensor curve's test on what every branch shares at equal displacement (round 19).

A sensor curve is a static map of the measured position: the same on every recording the sensor reads, whatever
the drive's history or rate. The same displacement reached rising and falling, on a fast triangle and on a dwell,
carries the same curve error; the base's misfit on histories the calibration did not show (minor-loop memory, the
unknown initial state) differs between those visits. The whole-residual test of :func:`select._evaluate` sizes a
curve against both, and the held-out sensor-curve misses of rounds 17 and 18 were refused there with the base's
in-range misfit beside the curve as large as the curve (0.5 to 2.5 times its RMS: docs/diagnose-rounds/round-18.md, "Round 18: the
sensor curve" and "Round 19: the sensor curve").

Here the residual is reduced to its *branch-common part* before anything is fitted or sized: the settled samples
are cut into branches (a new branch wherever the drive turns, :func:`branches`) and into bins of the model's
output; per bin, the mean over the branches that visit it of each branch's mean there. A static map of y passes
that average unchanged; a misfit that differs between branches at equal y averages towards its common part. The
curve is fitted (nested against the term's nuisance, reduced alike) on one fold's common part and predicts the
other fold's, the folds being the selection's alternate blocks; sized by the two fold ratios and tested by a
paired one-sided t-test on the bins' squared errors before and after. Being the sensor's, the map is also the same
on every recording (round 17's ``Term.same_on_every_recording``): :func:`across_recordings` fits it on the other
recordings' common parts and asks it to lower each recording's own (a misfit common to the branches of one
recording, or of one kind of history, does not carry over: null s121-041, x1.00 to x1.21 on its three).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse, stats

N_BINS = 24          # bins of the model's output over the settled samples (equal counts)
MIN_CELL = 5         # samples of one branch in one bin for its mean to count
MIN_BRANCHES = 2     # branches in a bin for a common part: a contrast needs two visits
TURN = 0.02          # the drive turns when it moves back by this fraction of its span (ignores noise-sized wiggles)

__all__ = ["branches", "common_averager", "branch_common_test", "across_recordings", "common_misfit", "N_BINS",
           "TURN"]


def branches(u: np.ndarray, turn: float = TURN) -> np.ndarray:
    """Branch id per sample of one recording: a new branch wherever the drive ``u`` [V] changes direction.

    Parameters
    ----------
    u : ndarray
        The drive [V].
    turn : float
        A direction change counts once the drive has moved back by ``turn`` times its span from its extreme.

    Returns
    -------
    ndarray of int
        0, 1, ... in order; a dwell keeps the branch of the movement that reached it.
    """
    u = np.asarray(u, float)
    out = np.zeros(u.size, int)
    if u.size == 0:
        return out
    w = turn * max(float(np.ptp(u)), 1e-12)
    ref, d, bid = float(u[0]), 0, 0
    for i, x in enumerate(u):
        if x > ref + w or (d > 0 and x > ref):
            if d < 0:
                bid += 1
            d, ref = 1, float(x)
        elif x < ref - w or (d < 0 and x < ref):
            if d > 0:
                bid += 1
            d, ref = -1, float(x)
        out[i] = bid
    return out


def common_averager(ybin: np.ndarray, branch: np.ndarray, n_bins: int = N_BINS):
    """The linear map from samples to the branch-common part, per bin.

    Parameters
    ----------
    ybin, branch : ndarray of int
        Bin and branch of each sample (one fold's samples).

    Returns
    -------
    (A, w) : (scipy.sparse.csr_matrix (m, n), ndarray (m,))
        Row k of ``A`` averages, over the branches visiting bin k with at least ``MIN_CELL`` samples, each branch's
        mean there; ``w`` the number of such branches. Only bins with ``MIN_BRANCHES`` or more. Sparse: each sample
        lies in one cell, so ``A`` has at most one entry per column (round 20: the dense form held bins x samples
        floats, 0.1 GB per fold at full length, and was filled one cell at a time).
    """
    key = np.asarray(branch, np.int64) * n_bins + np.asarray(ybin, np.int64)
    uk, inv = np.unique(key, return_inverse=True)
    inv = inv.ravel()
    cnt = np.bincount(inv)
    cell_bin = uk % n_bins
    ok = cnt >= MIN_CELL
    per_bin = np.bincount(cell_bin[ok], minlength=n_bins)   # counted cells (branches) per bin
    kept = np.flatnonzero(per_bin >= MIN_BRANCHES)
    row_of_bin = np.full(n_bins, -1)
    row_of_bin[kept] = np.arange(kept.size)
    cell_row = np.where(ok, row_of_bin[cell_bin], -1)
    row = cell_row[inv]
    col = np.flatnonzero(row >= 0)
    c = inv[col]
    weight = 1.0 / (cnt[c] * per_bin[cell_bin[c]])   # the sample's share of its cell's mean, of the bin's average
    A = sparse.csr_matrix((weight, (row[col], col)), shape=(kept.size, key.size))
    return A, per_bin[kept].astype(float)


def _binned(y):
    edges = np.quantile(y, np.linspace(0.0, 1.0, N_BINS + 1))
    return np.clip(np.searchsorted(edges, y, side="right") - 1, 0, N_BINS - 1)


def across_recordings(y: np.ndarray, branch: np.ndarray, rec: np.ndarray, e: np.ndarray, X: np.ndarray) -> dict:
    """Per recording: the columns ``X`` fitted on the other recordings' branch-common parts predict its own.

    Parameters
    ----------
    y, branch, e, X : ndarray
        As in :func:`branch_common_test` (all used samples; bins over all of them).
    rec : ndarray of int
        Recording index of each sample.

    Returns
    -------
    dict
        {recording index: RMS after / before of its common part (weighted by branches per bin)}, for each
        recording with more bins than columns while the others together have as many.
    """
    yb = _binned(y)
    red = {}
    for i in np.unique(rec):
        idx = np.flatnonzero(rec == i)
        A, w = common_averager(yb[idx], branch[idx])
        if w.size > X.shape[1]:
            red[int(i)] = (A @ e[idx], A @ X[idx], np.sqrt(w))
    out = {}
    for i, (e_i, x_i, s_i) in red.items():
        others = [r for j, r in red.items() if j != i]
        if sum(r[0].size for r in others) <= X.shape[1]:
            continue
        E, Z, S = (np.concatenate([r[0] for r in others]), np.vstack([r[1] for r in others]),
                   np.concatenate([r[2] for r in others]))
        th = np.linalg.lstsq(Z * S[:, None], E * S, rcond=None)[0]
        before = float(np.sum(s_i ** 2 * e_i ** 2))
        out[i] = float(np.sqrt(np.sum(s_i ** 2 * (e_i - x_i @ th) ** 2) / before)) if before > 0 else 1.0
    return out


def branch_common_test(y: np.ndarray, branch: np.ndarray, e: np.ndarray, X: np.ndarray, N: np.ndarray | None,
                       fold: np.ndarray) -> dict | None:
    """Cross-validated fit of the columns ``X`` on the branch-common part of the residual ``e``.

    Parameters
    ----------
    y : ndarray
        The model's output [um] on the used samples (binned by equal counts).
    branch : ndarray of int
        Branch id of each used sample, unique across recordings.
    e : ndarray
        The residual [um] on the used samples.
    X : ndarray (n, k)
        The term's columns (its own and its intercept).
    N : ndarray (n, m) or None
        The term's nested nuisance (refitted alone for "before", jointly for "after").
    fold : ndarray of int
        0/1 per used sample: the fit on fold f predicts fold 1 - f.

    Returns
    -------
    dict or None
        ``fold_ratios`` (RMS after / before of the held-out fold's common part, weighted by branches per bin;
        index f: fitted on fold f, scored on fold 1 - f, as in ``select._evaluate``), ``p`` (one-sided paired t-test on the bins of both
        held-out folds), ``n_bins``, ``before_um`` / ``after_um`` (the common part's weighted RMS); None when a fold
        has fewer bins than columns to fit; ``coef`` (round 20): per fold f, the columns' coefficients fitted on
        fold f's common part (jointly with the nuisance, whose coefficients are dropped), a model of the map sized
        where the base's history-dependent misfit averages out.
    """
    yb = _binned(y)
    Nn = np.zeros((e.size, 0)) if N is None else N
    red = {}
    for f in (0, 1):
        idx = np.flatnonzero(fold == f)
        A, w = common_averager(yb[idx], branch[idx])
        if w.size <= Nn.shape[1] + X.shape[1]:
            return None
        red[f] = (A @ e[idx], A @ X[idx], A @ Nn[idx], np.sqrt(w))
    ratios, d, b_all, a_all, w_all, coef = [], [], [], [], [], []
    for f in (0, 1):
        e_tr, x_tr, n_tr, s_tr = red[f]
        e_te, x_te, n_te, s_te = red[1 - f]
        before = e_te
        if n_tr.shape[1]:
            th0 = np.linalg.lstsq(n_tr * s_tr[:, None], e_tr * s_tr, rcond=None)[0]
            before = e_te - n_te @ th0
        Z, Zt = np.hstack([n_tr, x_tr]), np.hstack([n_te, x_te])
        th = np.linalg.lstsq(Z * s_tr[:, None], e_tr * s_tr, rcond=None)[0]
        coef.append([float(x) for x in th[n_tr.shape[1]:]])
        after = e_te - Zt @ th
        sb, sa = float(np.sum(s_te ** 2 * before ** 2)), float(np.sum(s_te ** 2 * after ** 2))
        ratios.append(float(np.sqrt(sa / sb)) if sb > 0 else 1.0)
        d.append(s_te ** 2 * (before ** 2 - after ** 2))
        b_all.append(before), a_all.append(after), w_all.append(s_te ** 2)
    d = np.concatenate(d)
    sd = float(np.std(d, ddof=1))
    p = float(stats.t.sf(np.mean(d) / (sd / np.sqrt(d.size)), d.size - 1)) if sd > 0 else 1.0
    w = np.concatenate(w_all)
    return {"fold_ratios": ratios, "p": p, "n_bins": int(d.size), "coef": coef,
            "before_um": float(np.sqrt(np.average(np.concatenate(b_all) ** 2, weights=w))),
            "after_um": float(np.sqrt(np.average(np.concatenate(a_all) ** 2, weights=w)))}


def common_misfit(holdout: list, drives: list, outputs: list) -> float | None:
    """The base's misfit on held-out calibration histories reduced to its branch-common part (round 26).

    The credited ratio of :func:`branch_common_test`'s reading subtracted the base's *whole* misfit energy per
    sample on unseen histories (round 19: an upper bound). Much of that misfit is the dynamics' lag, of opposite
    sign rising and falling at equal displacement, which the common part averages out as it does on the
    recordings, and the levels of unseen histories differ in sign between them. Each refit of the plane (one
    ``segment`` left out of every calibration recording at once) is one model predicting several histories it did
    not see, as the base predicts the recordings: its histories are reduced together as the recordings are
    (branches of each history's drive, ``N_BINS`` equal-count bins of the model's output over their scored
    samples), and the excess over the reference fit's common part on the same samples is pooled over the refits
    with the test's weights (branches per bin).

    Parameters
    ----------
    holdout : list of dict
        ``ident.base._holdout_histories``'s result: ``recording``, ``segment``, ``start``, ``stop``, ``resid`` and
        ``resid_in`` [um], ``scored``.
    drives, outputs : list of ndarray
        Per calibration recording its drive [V] and measured displacement [um] (the model's output over a history
        is the measured one less ``resid``).

    Returns
    -------
    float or None
        The excess energy per weighted bin [um^2] (held out minus seen, at least 0); None when no refit's
        histories hold a bin visited by two branches.
    """
    groups = {}
    for h in holdout:
        groups.setdefault(h.get("segment", 0), []).append(h)
    tot, tot_in, wsum = 0.0, 0.0, 0.0
    for hs in groups.values():
        y, br, r, r_in, n0 = [], [], [], [], 0
        for h in hs:
            a, b = int(h["start"]), int(h["stop"])
            m = np.asarray(h["scored"], bool)
            if not np.any(m):
                continue
            y.append((np.asarray(outputs[h["recording"]], float)[a:b] - np.asarray(h["resid"], float))[m])
            bh = branches(np.asarray(drives[h["recording"]], float)[a:b])[m] + n0   # unique across histories
            n0 = int(bh.max()) + 1
            br.append(bh)
            r.append(np.asarray(h["resid"], float)[m])
            r_in.append(np.asarray(h["resid_in"], float)[m])
        if not y:
            continue
        A, w = common_averager(_binned(np.concatenate(y)), np.concatenate(br))
        if w.size == 0:
            continue
        tot += float(np.sum(w * (A @ np.concatenate(r)) ** 2))
        tot_in += float(np.sum(w * (A @ np.concatenate(r_in)) ** 2))
        wsum += float(np.sum(w))
    if wsum <= 0:
        return None
    return max(tot - tot_in, 0.0) / wsum
