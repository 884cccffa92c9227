"""Round 22 (docs/diagnose.md, "Round 22: speed and memory"): the bounded solve runs on the design's triangular
factor instead of its rows, a term's grid predicts the held-out rows with its best setting only, and the discrete
mode filter is computed once per (frequency, damping, period). The first changes results by round-off only, the
other two by nothing."""

import numpy as np
from scipy import signal
from scipy.optimize import lsq_linear

from piezoctl import dsp
from piezoctl.diagnose import select as S
from piezoctl.diagnose import solve
from piezoctl.ident.terms import TERMS
from test_diagnose_speed_round20 import _two_contexts


def _whole(X, y, lo, hi):
    """Round 21's bounded solve: lsq_linear's BVLS on every row of the unit-RMS design."""
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    return lsq_linear(X / sc, y, bounds=(np.asarray(lo, float) * sc, np.asarray(hi, float) * sc), method="bvls",
                      lsq_solver="exact").x / sc


def _problem(rng, n, k, collinear=False):
    X = rng.normal(size=(n, k)) * rng.uniform(0.1, 10.0, k)
    if collinear:   # an exactly dependent column (a nuisance's offset beside a term's intercept)
        X[:, -1] = 2.0 * X[:, 0] + X[:, 1]
    y = X @ rng.normal(size=k) + rng.normal(size=n)
    lo = np.where(rng.random(k) < 0.5, 0.0, -np.inf)
    return X, y, lo


def test_the_reduced_bounded_solve_equals_the_solve_on_every_row_to_round_off():
    rng = np.random.default_rng(7)
    bound = 0
    for i in range(12):
        X, y, lo = _problem(rng, 20_000, int(rng.integers(3, 25)), collinear=i % 3 == 0)
        ref = _whole(X, y, lo, np.inf)
        new = solve.lstsq_box(X, y, lo, np.inf)
        assert np.max(np.abs(new - ref)) <= 1e-11 * np.max(np.abs(ref))
        assert np.array_equal(new == lo, ref == lo)   # the same coefficients on their bounds
        bound += int(np.sum(ref == lo))
    assert bound > 10   # the bounds acted (BVLS ran, not only the unbounded start)


def test_a_design_too_short_to_reduce_is_solved_as_before():
    rng = np.random.default_rng(8)
    X, y, lo = _problem(rng, 30, 8)
    assert 30 <= solve.REDUCE_ROWS_PER_COLUMN * 9
    assert np.array_equal(solve.lstsq_box(X, y, lo, np.inf), _whole(X, y, lo, np.inf))


def test_the_mode_filter_is_the_zero_order_hold_mode_and_a_fresh_copy_per_call():
    w = 2.0 * np.pi * 988.0
    bd, ad, _ = signal.cont2discrete(([w * w], [1.0, 2.0 * 0.016 * w, w * w]), 1e-4, method="zoh")
    b, a = dsp.mode_filter(988.0, 0.016, 1e-4)
    assert np.array_equal(b, np.ravel(bd)) and np.array_equal(a, np.ravel(ad))
    b[:] = 0.0   # a caller that writes into its copy does not change the next one's
    b2, _ = dsp.mode_filter(988, np.float64(0.016), 1e-4)
    assert np.array_equal(b2, np.ravel(bd))


def test_best_setting_predicts_with_its_best_setting_only_and_returns_what_every_setting_predicted_gave():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    e = S.residual(ctx)
    train, test = fold_all == 0, fold_all == 1
    rows = 10 ** 6
    for nuis in (None, S._nuis(ctx, term, train, test, rows)):
        st, d, sse, pa, th = S.best_setting(ctx, term, e, train, test, rows, nuis)
        # round 21's loop: every setting fitted and predicted, the least training error kept
        best, level, settings, new = None, {}, term.settings(ctx), 0
        for _ in range(3):
            for s in settings:
                if repr(s) in level:
                    continue
                level[repr(s)] = new
                t, p, q = S._fit_predict(S._design(ctx, term, s).X, e, train, test, rows, term.lower(ctx), nuis)
                if best is None or q < best[2]:
                    best = (s, None, q, p, t if nuis is None else t[nuis[0].shape[1]:])
            new = level[repr(best[0])] + 1
            settings = term.refine(ctx, best[0], new) if new <= 2 else []
            if not settings:
                break
        assert st == best[0] and sse == best[2]
        assert np.array_equal(pa, best[3]) and np.array_equal(th, best[4])
        assert pa.shape == (int(np.sum(test)),)
