"""Round 22 (docs/diagnose-rounds/round-22.md, "Round 22: speed and memory"): a term's grid predicts the held-out rows with its best
setting only, and the discrete mode filter is computed once per (frequency, damping, period). Neither changes a
result."""

import numpy as np
from scipy import signal

from piezoctl import dsp
from piezoctl.diagnose import select as S
from piezoctl.ident.terms import TERMS
from test_diagnose_speed_round20 import _two_contexts


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
