"""Round 19: creep's model sized on the dwells after the drive's steps (slow_signature.py, ``dwell_taus``,
``creep_coef_on_dwells``, ``creep_model_on_dwells``): the time constants a dwell can size, gains >= 0 taken from
the step-locked tails alone, the base's loop kept, and nothing where the dwells show no tail."""

import types

import numpy as np

from piezoctl.diagnose.slow_signature import creep_coef_on_dwells, creep_model_on_dwells, dwell_taus
from piezoctl.dsp import filt
from piezoctl.ident.terms import TERMS
from test_diagnose_slow import _creep, _ctx, _measured
from test_slow_signature_steps import LP, _with_dynamics

ROWS = 200000


def _coef(ctx, effect, seed):
    e, fold, block = _measured(ctx, effect, np.random.default_rng(seed))
    return creep_coef_on_dwells(ctx, e, fold == 0, ROWS), e, fold, block


def _parts(ctx, coef):
    n = TERMS["creep"].n_nuisance(ctx)
    return coef[:n], coef[n:-1], coef[-1]


def test_the_dwells_size_only_time_constants_up_to_the_longest_dwell():
    """The synthetic recordings hold each level 2 s and 1.5 s; a dwell starts once G and the longest delay settled,
    so the longest is under 2 s: 0.1, 0.3 and 1 s can be sized, 3 and 10 s (a straight line over it) cannot."""
    ctx = _with_dynamics(_ctx(np.random.default_rng(1)))
    taus = TERMS["creep"].taus(ctx)
    assert taus == [0.1, 0.3, 1.0, 3.0, 10.0]
    assert dwell_taus(ctx, taus) == [0.1, 0.3, 1.0]
    coef, *_ = _coef(ctx, lambda s: filt(*LP, _creep(s)), 2)
    groups, gains, _ = _parts(ctx, coef)
    assert np.all(groups == 0.0)   # the base's loop is kept
    assert np.all(gains >= 0.0) and np.all(gains[3:] == 0.0)
    # the log law's first decades (g = 3 %/decade from t0 = 50 ms): the three elements carry a share of it
    assert 0.01 < gains.sum() < 0.1, gains


def test_a_misfit_between_the_steps_does_not_move_the_gains():
    """The reason for the change (development s121-000, s121-046): a slow base misfit where the drive is not held
    (here 0.3 um on the triangle, six times creep's tail) leaves the gains sized on the dwells as they were; only
    the constant takes its mean."""
    ctx = _with_dynamics(_ctx(np.random.default_rng(3)))
    creep = lambda s: filt(*LP, _creep(s))
    coef0, *_ = _coef(ctx, creep, 4)
    tri = lambda s: creep(s) + (0.3 * np.sin(2 * np.pi * s.t / 5.0) + 0.1 if s.name == "rec1" else 0.0)
    coef1, *_ = _coef(ctx, tri, 4)
    g0, g1 = _parts(ctx, coef0)[1], _parts(ctx, coef1)[1]
    assert np.allclose(g0, g1, atol=1e-12)
    assert abs(_parts(ctx, coef1)[2] - _parts(ctx, coef0)[2]) > 0.01


def _cand(significant=True):
    return types.SimpleNamespace(name="creep", significant=significant, veto=None, p_max=1e-3, dwell_coef=None)


def test_the_dwells_model_is_offered_only_where_the_step_test_holds():
    for effect, offered in ((lambda s: filt(*LP, _creep(s)), True), (lambda s: np.zeros(s.t.size), False)):
        ctx = _with_dynamics(_ctx(np.random.default_rng(5)))
        e, fold, block = _measured(ctx, effect, np.random.default_rng(6))
        c = _cand()
        creep_model_on_dwells([c], [ctx, ctx], [e, e], fold, block, ROWS, lambda *a: None)
        assert (c.dwell_coef is not None) is offered
        if offered:
            assert len(c.dwell_coef) == 2 and all(x.size == len(TERMS["creep"].regressors(ctx, ctx.signals[0], None)[0])
                                                  for x in c.dwell_coef)
    # a candidate that did not pass its own test gets none, whatever its dwells show
    ctx = _with_dynamics(_ctx(np.random.default_rng(5)))
    e, fold, block = _measured(ctx, lambda s: filt(*LP, _creep(s)), np.random.default_rng(6))
    c = _cand(significant=False)
    creep_model_on_dwells([c], [ctx, ctx], [e, e], fold, block, ROWS, lambda *a: None)
    assert c.dwell_coef is None


def test_no_dwell_no_model():
    ctx = _with_dynamics(_ctx(np.random.default_rng(7)))
    for i in (0, 2):   # the step recordings never held: a dither on every sample
        ctx.signals[i].u = ctx.signals[i].u + 1e-3 * np.sin(np.arange(ctx.signals[i].u.size))
    coef, *_ = _coef(ctx, lambda s: filt(*LP, _creep(s)), 8)
    assert coef is None


def test_the_exact_check_takes_the_dwells_model_only_after_the_all_blocks_model_is_refused(monkeypatch):
    """select._first_exact: the creep model fitted on all blocks first; refused, the dwells' model (``dwell_coef``)
    is checked and, when it lowers the error in each fold, becomes the candidate's model; refused too, no name."""
    from piezoctl.diagnose import select as S
    fctx = [types.SimpleNamespace(names=["steps", "triangle"])] * 2
    all_blocks, dwells = np.zeros(3), np.ones(3)

    def cand(after_dwells):
        sse = {id(all_blocks): 1.2, id(dwells): after_dwells}

        def exact(ctx, c, f, fold_all, recs):
            a = sse[id(c.coef[f])]
            return {"sse_before": 1.0, "sse_after": a, "n": 10, "per_recording": [(0.5, 0.5 * a), (0.5, 0.5 * a)],
                    "params": {}}
        monkeypatch.setattr(S, "_exact_fold", exact)
        c = S.Candidate(term=TERMS["creep"], ratio=0.9, fold_ratios=[0.9, 0.9], nrmse_before=0.02, nrmse_after=0.018,
                        t=5.0, p=1e-9, n_active=40, p_max=1e-3, dbic=-50.0, n_eff=500.0, significant=True,
                        setting=[None, None], coef=[all_blocks, all_blocks], credited=0.9)
        c.dwell_coef = [dwells, dwells]
        return c

    c = cand(0.81)
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is c
    assert c.from_dwells and c.veto is None and c.coef[0] is dwells
    assert c.exact_fold_ratios == [np.sqrt(0.81)] * 2 and "sized on the dwells" in c.discrimination
    c = cand(1.1)
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is None
    assert not c.from_dwells and c.coef[0] is all_blocks and "nor sized on the dwells" in c.veto
    c = cand(0.81)
    c.dwell_coef = None   # no dwells' model (its step test did not hold): the refusal stands
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is None and "exact simulation" in c.veto
