"""Round 26 (docs/diagnose-rounds/round-26.md, "Round 26: speed"): a fit reads a design's training rows (and the
nuisance fit its nuisance columns) without stacking the whole design, and a narrowing design of the rate term
shares its constant shift columns with its family's first design. Neither changes a float."""

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.ident.terms import TERMS
from test_diagnose_speed_round20 import _rate_evaluation, _two_contexts


def test_rows_and_columns_of_a_design_are_the_bits_of_the_stacked_design():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    settings = term.settings(ctx)
    ds = [S._design(ctx, term, st) for st in settings]
    assert ds[0]._X is not None and all(d._X is None for d in ds[1:])   # kept stacked, then shared columns
    rng = np.random.default_rng(0)
    idx = np.sort(rng.choice(ds[0].n, ds[0].n // 3, replace=False))
    for d in (ds[0], ds[1], ds[-1]):
        X = d.X
        r = d.rows(idx)
        assert r.shape == (idx.size, d.k) and r.strides == X[idx].strides
        assert np.array_equal(r.view(np.int64), X[idx].view(np.int64))
        cols = term.nuisance_columns(ctx, d.k)
        c, ref = d.take(cols), X[:, cols]
        assert c.shape == ref.shape and c.strides == ref.strides   # the same layout: BLAS sums alike
        assert np.array_equal(c.view(np.int64), ref.view(np.int64))


def test_a_fit_on_a_design_equals_the_fit_on_its_stacked_rows():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    settings = term.settings(ctx)
    d = [S._design(ctx, term, st) for st in settings][-1]   # a narrowing: shares columns with two designs
    assert d._X is None and term.family(d.setting) == "narrow"
    e = S.residual(ctx)
    train = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)]) == 0
    test = ~train
    lb = term.lower(ctx)
    for kw in ({"lb": lb, "rows": 500}, {"lb": None, "rows": 10 ** 6}):
        a = S._fit_predict(d, e, train, test, kw["rows"], kw["lb"])
        b = S._fit_predict(d.X, e, train, test, kw["rows"], kw["lb"])
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
    own = term.nuisance_columns(ctx, d.k)   # the family's "before" (best_setting's score, _evaluate)
    a = S._fit_predict(d.take(own), e, train, test, 10 ** 6)
    b = S._fit_predict(d.X[:, own], e, train, test, 10 ** 6)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]


def test_the_rate_candidate_is_the_same_without_the_family_reference(monkeypatch):
    _, _, run = _rate_evaluation()
    shared = run()
    made = S._Design.__init__
    # round 25's sharing: the term's first design only
    monkeypatch.setattr(S._Design, "__init__", lambda self, c, t, st, ref=None: made(self, c, t, st, ref[:1]))
    first_only = run()
    assert shared.setting == first_only.setting
    assert shared.fold_ratios == first_only.fold_ratios and shared.p == first_only.p
    assert shared.ratio == first_only.ratio and shared.credited == first_only.credited
    assert all(np.array_equal(a, b) for a, b in zip(shared.coef, first_only.coef))
