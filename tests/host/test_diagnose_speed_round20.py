"""Round 20 (docs/diagnose-rounds/round-20.md, "Round 20: speed and memory"): of fold 0's designs only its chosen settings are kept
while fold 1 (its own context, after the first round) is evaluated; the candidate is the same as with every design
kept."""

import copy

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.run import locate
from piezoctl.ident import refined
from piezoctl.ident.terms import TERMS
from piezoctl.io.recording import Recording
from test_diagnose_rate import _stage


def _two_contexts():
    rng = np.random.default_rng(3)
    base, t, drives = _stage(rng)
    true = {"gain": 1.0, "ref_fs_per_s": 10.0, "width_k": 0.8, "rate_cutoff_hz": 50.0}
    stage = dict(base, terms={"rate_dependent_hysteresis": true})
    recs = [Recording(t=t, u=u, y=refined.simulate(stage, t, u) + rng.normal(0, 0.005, t.size), path=f"r{i}.csv")
            for i, u in enumerate(drives)]
    ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
    other = copy.copy(ctx)            # a second fold context, as after the first accepted term: its own caches
    other.design_cache = {}
    return ctx, other


def _rate_evaluation():
    """The rate term, two fold contexts, and a function that evaluates the term on them (its candidate)."""
    term = TERMS["rate_dependent_hysteresis"]
    ctx, other = _two_contexts()
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = S.residual(ctx)

    def run():
        return S._evaluate([ctx, other], term, [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12)
    return term, ctx, run


def test_fold_zero_keeps_only_its_chosen_designs_and_the_candidate_is_unchanged(monkeypatch):
    term, ctx, run = _rate_evaluation()

    kept, keep0 = [], S._keep_designs

    def spy(c, t, settings):
        before = len(c.design_cache)
        keep0(c, t, settings)
        kept.append((c is ctx, before, sorted(c.design_cache)))
    monkeypatch.setattr(S, "_keep_designs", spy)
    pruned = run()
    assert len(kept) == 1 and kept[0][0]                       # once, on fold 0's context
    assert kept[0][1] > 4 and 1 <= len(kept[0][2]) <= 2       # the grid's designs, then the chosen settings'
    assert (term.name, repr(pruned.setting[0])) in kept[0][2]  # the model's setting of fold 0 among them
    monkeypatch.setattr(S, "_keep_designs", lambda *a: None)   # every design kept (round 19)
    full = run()
    assert pruned.setting == full.setting
    assert pruned.fold_ratios == full.fold_ratios and pruned.p == full.p and pruned.ratio == full.ratio
    assert all(np.array_equal(a, b) for a, b in zip(pruned.coef, full.coef))
    assert pruned.significant == full.significant and pruned.veto == full.veto


def test_the_first_round_keeps_every_design_for_fold_one(monkeypatch):
    ctx, _ = _two_contexts()
    calls = []
    monkeypatch.setattr(S, "_keep_designs", lambda *a: calls.append(a))
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = S.residual(ctx)
    S._evaluate([ctx, ctx], TERMS["rate_dependent_hysteresis"], [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12)
    assert calls == []   # one context for both folds: fold 1 reuses fold 0's designs
