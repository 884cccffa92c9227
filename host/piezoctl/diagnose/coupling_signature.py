"""Cross-axis coupling's signature: its improvement must follow the other axis' *motion* (round 14, issue 12
item 2, "coupling following the other axis").

The coupling term's columns (``ident.terms.CrossCoupling``: ``G[u2] - u2_ref``, its acceleration, its product
with the position) depend on the other axis' drive ``u2`` in two ways: through its *level* in each recording and
through its *motion* within the recording. Only the motion is coupling's own. A level of ``u2`` that differs
from one recording to the next makes the static column a constant per recording and the product column a gain
on the position per recording: where the other axis is held at one value in every recording but one (a null
whose last recording moves it, development case s111-016), the coupling's columns take that recording's level
and slope, i.e. a drift's or an offset's (round 13: ``cross_coupling`` named second for a drift at fold ratios
0.44/0.49, p = 2.4e-7).

:func:`motion_test` splits the columns at the candidate's setting into the part with ``u2`` held at its mean
over each recording's settled samples (``X0``: the level part) and the rest (``Xm = X - X0``: the motion part,
zero wherever the other axis is still), and tests the motion part's *unique* held-out contribution beyond:

- the level part and a constant per recording (whatever sets a level or a gain per recording),
- the slow signatures' groups (``slow_signature.signature_groups``: creep's transients, the drift's curve on the
  session clock, the sensor-zero columns) and their nuisance (``select.slow_nuisance``: the model's hysteresis
  groups, the initial state), so that a drift's or creep's trend is offered to its own columns first.

Fitted on one fold of the ~1 s blocks and scored on the other (the same folds and blocks as the selection),
``significance.active_block_test`` gives p. The signature *holds* when p < ``significance.ALPHA`` (one
pre-specified hypothesis: that a candidate which passed its own test is coupling) and the held-out error falls
in each fold. The level is a test level; nothing was set from a case.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..ident.terms import TERMS
from . import significance as sg
from .solve import lstsq_box, train_rows

__all__ = ["motion_columns", "motion_test", "motion_phrase"]


def motion_columns(ctx, s, v, setting) -> tuple[np.ndarray, np.ndarray]:
    """The coupling's columns of recording ``s`` at ``setting``, split: (motion part, level part), each (n, k).

    The level part is the columns with ``u2`` held at its mean over the recording's settled samples ``v``; the
    motion part is the rest (zero where ``u2`` does not move). None of ``u2``: both zero."""
    term = TERMS["cross_coupling"]
    X = np.asarray(term.columns(ctx, s, setting), float)
    if s.u2 is None:
        return np.zeros_like(X), np.zeros_like(X)
    u2 = np.asarray(s.u2, float)
    held = dataclasses.replace(s, u2=np.full(u2.size, float(np.mean(u2[v])) if np.any(v) else float(u2[0])))
    X0 = np.asarray(term.columns(ctx, held, setting), float)
    return X - X0, X0


RANK_TOL = 1e-6   # singular values below this fraction of the largest are dropped: combinations of the columns
#                  below the recorded data's precision (9 digits, as slow_signature.STEP_STILL); the acceleration of
#                  a pure sine is the sine times a constant except at the recording's ends, which a fold may hold


def _spanning(X, train) -> np.ndarray:
    """Free columns ``X`` replaced by an orthogonal basis of their span on the training rows (unit-RMS columns,
    numerical rank at ``RANK_TOL``): collinear on the training rows but not on the test rows, their coefficients
    would cancel in the fit and not in the prediction."""
    if X.shape[1] == 0:
        return X
    sc = np.sqrt(np.mean(X[train] ** 2, axis=0))
    keep = sc > 0
    if not np.any(keep):
        return X[:, :0]
    Xs = X[:, keep] / sc[keep]
    _, sv, vt = np.linalg.svd(Xs[train], full_matrices=False)
    return Xs @ vt[sv > RANK_TOL * sv[0]].T


def motion_test(ctxs, es, nuisances, settings, fold_all, block_all, rows) -> dict:
    """The coupling's motion beyond its level, the slow signatures and a level per recording (module docstring).

    Parameters
    ----------
    ctxs, es : list
        Per fold f: the current model fitted on fold f (``select.Ctx``) and its residual [um] (settled samples,
        stacked).
    nuisances : list
        Per fold: (columns, lower, upper bounds) of the slow signatures' nuisance (``select.slow_nuisance``).
    settings : list
        Per fold: the coupling candidate's setting (None, or a mode's (Hz, damping)).
    fold_all, block_all : ndarray of int
        Fold (-1: not used) and block of each settled sample.
    rows : int
        The most training rows a fit uses.

    Returns
    -------
    dict
        ``ratio`` and ``fold_ratios`` (held-out RMS with the motion part / without, pooled and per fold), ``p``,
        ``n_active``, ``holds``, ``alpha``, ``moving_fraction`` (of the settled samples where the motion part is
        not zero).
    """
    from .slow_signature import SIGNATURES, signature_groups
    ctx0 = ctxs[0]
    rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(ctx0.valid)])
    R = (rec[:, None] == np.arange(ctx0.n_rec)[None, :]).astype(float)
    small, big = np.zeros(fold_all.size), np.zeros(fold_all.size)
    moving = np.zeros(fold_all.size, bool)
    for f in (0, 1):
        ctx = ctxs[f]
        parts = [motion_columns(ctx, s, v, settings[f]) for s, v in zip(ctx.signals, ctx.valid)]
        train, test = fold_all == f, fold_all == 1 - f
        Xm = np.vstack([m[v] for (m, _), v in zip(parts, ctx.valid)])
        moving |= np.any(np.abs(Xm) > 0, axis=1)
        X0 = _spanning(np.hstack([R, np.vstack([l[v] for (_, l), v in zip(parts, ctx.valid)])]), train)
        # what the motion part shares with the level part on the training rows is the level's (both are free)
        Xm = Xm - X0 @ np.linalg.lstsq(X0[train], Xm[train], rcond=None)[0]
        Xm = _spanning(Xm, train)
        N, n_lo, n_hi = nuisances[f]
        groups = signature_groups(ctx)
        names = [n for n in SIGNATURES if n in groups and n != "sensor_offset"]   # R spans the sensor zero
        Z = np.hstack([N, X0] + [groups[n][0] for n in names])
        z_lo = np.concatenate([n_lo, np.full(X0.shape[1], -np.inf)] + [groups[n][1] for n in names])
        z_hi = np.concatenate([n_hi, np.full(Z.shape[1] - n_hi.size, np.inf)])
        idx = train_rows(train, rows)
        small[test] = Z[test] @ lstsq_box(Z[idx], es[f][idx], z_lo, z_hi)
        X = np.hstack([Z, Xm])
        lo = np.concatenate([z_lo, np.full(Xm.shape[1], -np.inf)])
        hi = np.concatenate([z_hi, np.full(Xm.shape[1], np.inf)])
        big[test] = X[test] @ lstsq_box(X[idx], es[f][idx], lo, hi)
    e = np.zeros(fold_all.size)
    for f in (0, 1):
        e[fold_all == 1 - f] = es[f][fold_all == 1 - f]
    used = fold_all >= 0
    before, after, corr = (e - small)[used], (e - big)[used], (big - small)[used]
    fr = sg.fold_ratios(before, after, fold_all[used])
    sb = float(np.sum(before ** 2))
    units = sg.test_units(before, block_all[used], rec[used], ctx0.dt, corr)
    _, p, n_act = sg.active_block_test(before, after, corr, block_all[used], units)
    return {"ratio": float(np.sqrt(np.sum(after ** 2) / sb)) if sb > 0 else 1.0, "fold_ratios": fr,
            "p": float(p), "n_active": int(n_act), "alpha": sg.ALPHA,
            "holds": bool(p < sg.ALPHA and max(fr) < 1.0),
            "moving_fraction": float(np.mean(moving[used])) if np.any(used) else 0.0}


def motion_phrase(mt: dict) -> str:
    """:func:`motion_test` in words."""
    return (f"the other axis' motion beyond its level per recording and the slow terms: ratio {mt['ratio']:.2f} "
            f"(folds {mt['fold_ratios'][0]:.2f}/{mt['fold_ratios'][1]:.2f}), p = {mt['p']:.1e} on {mt['n_active']} "
            f"active blocks; u2 moves in {100 * mt['moving_fraction']:.0f} % of the samples")
