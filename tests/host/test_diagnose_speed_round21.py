"""Round 21 (docs/diagnose-rounds/round-21.md, "Round 21: speed and memory"): a term's designs share the columns that are equal for
every setting (the rate term's constant widenings and intercept; round 26: a narrowing's constant shifts with its
family's first design) instead of a copy per setting; the base dynamics'
slow tail and the held samples are computed once per context. Neither changes a result."""

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.diagnose import slow_signature as ss
from piezoctl.ident.terms import TERMS
from test_diagnose_slow import _ctx, _measured
from test_diagnose_speed_round20 import _rate_evaluation, _two_contexts
from test_slow_base_tail import ROWS, _slow_base
from test_slow_signature_steps import LP


def _stacked(ctx, term, st):
    """The design as round 20 stacked it: each recording's regressors on its settled rows."""
    return np.vstack([np.asarray(term.regressors(ctx, s, st), float)[v] for s, v in zip(ctx.signals, ctx.valid)])


def test_rate_designs_share_the_columns_equal_for_every_setting_and_stack_the_same_floats():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    settings = term.settings(ctx)
    ds = [S._design(ctx, term, st) for st in settings]
    first = ds[0]
    nuisance = term.nuisance_columns(ctx, first.k)   # the constant widenings and shifts, and the intercept
    assert len(nuisance) == first.k - 1 and len(settings) > 4
    # round 25: a widening's shift columns are zero, a narrowing's are not: a narrowing shares with the first
    # design (a widening) the constant widenings and the intercept only
    shifts = list(range(len(term.CONSTANT_K), term.n_nuisance(ctx)))
    assert shifts and term.family(settings[0]) == "widen"
    assert {term.family(st) for st in settings} == {"widen", "narrow"}
    first_narrow = next(d for d, st in zip(ds, settings) if term.family(st) == "narrow")
    for d, st in zip(ds, settings):
        X = d.X
        assert X.flags.c_contiguous and X.shape == (d.n, d.k)
        assert np.array_equal(X.view(np.int64), _stacked(ctx, term, st).view(np.int64))   # the same bits
        narrow = term.family(st) == "narrow"
        assert all(np.any(X[:, j] != 0.0) == narrow for j in shifts)
        shared = [j for j in nuisance if not (narrow and j in shifts)]
        if d is not first:
            assert all(d.col(j).base is first.X for j in shared)   # views of the first design's columns
            own = [j for j in range(d.k) if j not in shared]
            assert all(d.col(j).base is not first.X for j in own)
            # round 26: a narrowing after its family's first shares that design's shift columns (the same arrays)
            later = narrow and d is not first_narrow
            if later:
                assert all(d.col(j) is first_narrow.col(j) for j in shifts)
            assert d.own_nbytes == (len(own) - (len(shifts) if later else 0)) * d.n * 8
        if narrow and d is first_narrow:
            assert all(d.col(j).base is None for j in shifts)   # its own copies
    assert first.own_nbytes == first.k * first.n * 8 and first.X is first.X   # kept stacked: shares nothing


def test_a_column_that_differs_in_one_bit_or_a_zero_sign_is_not_shared():
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    st = term.settings(ctx)
    first = S._design(ctx, term, st[0])
    first.X[7, -1] = -0.0 if first.X[7, -1] == 0.0 else np.nextafter(first.X[7, -1], 2.0)
    d = S._design(ctx, term, st[1])
    assert d.col(-1).base is not first.X and d.col(0).base is first.X
    assert np.all(d.col(-1) == 1.0)   # its own intercept, not the altered one


def test_the_rate_candidate_is_the_same_with_shared_columns(monkeypatch):
    _, _, run = _rate_evaluation()
    shared = run()
    made = S._Design.__init__
    monkeypatch.setattr(S._Design, "__init__", lambda self, c, t, st, ref=None: made(self, c, t, st, None))
    copies = run()   # every design its own copy of every column (round 20's memory)
    assert shared.setting == copies.setting
    assert shared.fold_ratios == copies.fold_ratios and shared.p == copies.p and shared.ratio == copies.ratio
    assert all(np.array_equal(a, b) for a, b in zip(shared.coef, copies.coef))
    assert shared.significant == copies.significant and shared.veto == copies.veto


def test_the_base_tail_is_computed_once_per_context_and_equals_a_fresh_one(monkeypatch):
    ctx = _slow_base(_ctx(np.random.default_rng(1)))
    e, fold, block = _measured(ctx, lambda s: np.zeros(s.h.size), np.random.default_rng(2))
    calls = []
    held0 = ss._held
    monkeypatch.setattr(ss, "_held", lambda s: calls.append(s) or held0(s))
    st = ss.step_response_test([ctx, ctx], [e, e], fold, block, ROWS)
    assert st is not None and st["base_tail"] == [True, True]
    assert len(calls) == len(ctx.signals)   # once per recording, though dwell_ids and base_tail both ask
    parts = ss._base_tail_parts(ctx)
    assert parts is ss._base_tail_parts(ctx) and not parts[0].flags.writeable
    again = ss.step_response_test([ctx, ctx], [e, e], fold, block, ROWS)
    assert len(calls) == len(ctx.signals)
    ctx.refit_cache.clear()   # recomputed from nothing: the same figures
    fresh = ss.step_response_test([ctx, ctx], [e, e], fold, block, ROWS)
    assert st == again == fresh


def test_a_new_base_recomputes_the_tail():
    ctx = _ctx(np.random.default_rng(1))
    dw, _, _ = ss._dwell_samples(ctx)
    m = dw >= 0
    assert ss.base_tail(ctx, m, dw[m]) is None   # G = 1: no tail
    before = ss._base_tail_parts(ctx)
    ctx.base = dict(ctx.base, dynamics={"b": list(LP[0]), "a": list(LP[1])})   # a new model: a new dict
    after = ss._base_tail_parts(ctx)
    assert after is not before and np.max(np.abs(after[0])) > np.max(np.abs(before[0]))


def test_dynamics_changed_in_place_recompute_the_tail():
    ctx = _ctx(np.random.default_rng(1))
    before = ss._base_tail_parts(ctx)
    ctx.base["dynamics"] = {"b": list(LP[0]), "a": list(LP[1])}   # the same model dict, its dynamics replaced
    after = ss._base_tail_parts(ctx)
    assert after is not before and np.max(np.abs(after[0])) > np.max(np.abs(before[0]))


def test_the_nuisance_rows_are_the_rows_of_the_stacked_nuisance():
    """``_nuis`` takes each block's rows and stacks them: the very bits of the stacked nuisance's rows."""
    term = TERMS["rate_dependent_hysteresis"]
    ctx, _ = _two_contexts()
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    N = S.term_nuisance(ctx, term)
    assert N is not None and len(S._nuisance_parts(ctx, term)) >= 2
    for f in (0, 1):
        train, test = fold_all == f, fold_all == 1 - f
        Ntr, Nte, bounds = S._nuis(ctx, term, train, test, 5000)
        idx = S.train_rows(train, 5000)
        assert Ntr.flags.c_contiguous and Nte.flags.c_contiguous
        assert np.array_equal(Ntr.view(np.int64), N[idx].view(np.int64))
        assert np.array_equal(Nte.view(np.int64), N[test].view(np.int64))
        assert bounds == S.nuisance_bounds(ctx, term, N)
