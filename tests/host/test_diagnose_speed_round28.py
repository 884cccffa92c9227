"""Round 28 (docs/diagnose-rounds/round-28.md, "Round 28: speed"): a design's settled rows are gathered by
``np.take`` (no buffered copy), and the base's last plane fit and its held-out histories share one filtering of
the plane columns. Neither changes a float. (A shared design's training rows gathered through its transpose were
tried and reverted: slower on s0-017; the test of their layout stays.)"""

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.ident import base as B
from piezoctl.ident.terms import TERMS
from test_diagnose_speed_round20 import _two_contexts
from test_diagnose_speed_round25 import _calibration
from base_compare import assert_same_base


def test_a_design_is_the_bits_of_its_masked_and_stacked_regressors():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    assert any(not np.all(v) for v in ctx.valid)   # some samples are not settled: the gather has work to do
    for st in term.settings(ctx)[:3]:
        d = S._design(ctx, term, st)
        ref = np.vstack([np.asarray(term.regressors(ctx, s, st), float)[v] for s, v in zip(ctx.signals, ctx.valid)])
        X = d.X
        assert X.shape == ref.shape and X.flags["C_CONTIGUOUS"]
        assert np.array_equal(X.view(np.int64), ref.view(np.int64))


def test_the_rows_of_a_shared_design_are_c_ordered_at_any_count():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    ds = [S._design(ctx, term, st) for st in term.settings(ctx)]
    d = ds[-1]
    assert d._X is None                                 # a shared design: rows gathered column by column
    X = d.X
    for idx in (np.zeros(0, int), np.array([0, d.n - 1]), np.arange(0, d.n, 7)):
        r = d.rows(idx)
        assert r.shape == (idx.size, d.k) and r.flags["C_CONTIGUOUS"]
        assert np.array_equal(r.view(np.int64), X[idx].view(np.int64))


def test_the_base_fit_filters_its_last_plane_columns_once_and_is_the_same_floats(monkeypatch):
    recs = _calibration()
    made = []
    orig = B._filtered_plane_columns

    def counting(*a):
        made.append(1)
        return orig(*a)

    monkeypatch.setattr(B, "_filtered_plane_columns", counting)
    new = B.fit_base(recs, holdout=True)
    assert new["base_info"]["dynamics_order"] > 0 and len(made) == len(recs)   # once per recording, shared
    fit, hold = B._fit_plane, B._holdout_histories
    # round 27's code path: each function filters the columns itself
    monkeypatch.setattr(B, "_fit_plane", lambda *a: fit(*a[:10]))
    monkeypatch.setattr(B, "_holdout_histories", lambda *a: hold(*a[:10]))
    made.clear()
    old = B.fit_base(recs, holdout=True)
    assert len(made) == 2 * len(recs)                # fit_base's, unused by the fit, and the histories' own
    assert_same_base(new, old)                        # every parameter and held-out history, bit for bit
