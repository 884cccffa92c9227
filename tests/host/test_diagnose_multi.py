"""The second effect (docs/diagnose-rounds/round-11.md, "Round 11: the second effect"): after the first term, a term with a
signature test of its own is tested with the size gates at FURTHER_RATIO_MAX and must then hold its signature."""

import numpy as np
import pytest

from piezoctl.diagnose import select as S
from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.slow_signature import attribute, signature_tests
from piezoctl.ident.terms import TERMS

from test_diagnose_slow import NOISE_UM, _creep, _ctx

ROWS = 200_000
SLOW = ("creep", "thermal_drift", "sensor_offset")


def _left(s, w=0.1):
    """What the model with its first term leaves besides the second effect [um]: an error with no history (a
    fast misfit of the dynamics, the first term's own error), the same in every recording's statistics."""
    return w * np.random.default_rng(100 + s.index).normal(size=s.t.size)


def _setup(effect, seed):
    rng = np.random.default_rng(seed)
    ctx = _ctx(rng)
    for s in ctx.signals:
        s.y = s.yb + effect(s) + NOISE_UM * rng.normal(size=s.t.size)
    fold = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    return ctx, fold, block, S.residual(ctx)


def _round(ctx, fold, block, e, accepted):
    """The slow candidates of one round at the loop's gates (``accepted``: the terms already in the model), then
    the loop's signature steps; the candidates and the names kept."""
    p_max = sg.ALPHA / (12 - len(accepted))
    evals = sorted((S._evaluate([ctx, ctx], TERMS[n], [e, e], fold, block, ROWS, p_max,
                                S._ratio_max(TERMS[n], accepted)) for n in SLOW), key=lambda c: c.ratio)
    if any(c.significant and not c.veto for c in evals):
        tests = signature_tests([ctx, ctx], [e, e], [S.slow_nuisance(ctx)] * 2, fold, block, ROWS)
        attribute(evals, tests)
        S._slow_beyond_gates(evals, lambda *a: None)
    return evals, [c.name for c in evals if c.significant and not c.veto]


def test_size_gates_by_round():
    assert S._ratio_max(TERMS["thermal_drift"], []) == sg.RATIO_MAX
    assert S._ratio_max(TERMS["thermal_drift"], ["a term"]) == S.FURTHER_RATIO_MAX
    assert S._ratio_max(TERMS["creep"], ["a term"]) == S.FURTHER_RATIO_MAX
    assert S._ratio_max(TERMS["delay"], ["a term"]) == S.FURTHER_RATIO_MAX
    # round 18: the coupling's motion test tells it from a base misfit and a drift (test_coupling_signature.py)
    assert S._ratio_max(TERMS["cross_coupling"], ["a term"]) == S.FURTHER_RATIO_MAX
    assert S._ratio_max(TERMS["cross_coupling"], []) == sg.RATIO_MAX
    # no signature test of its own, or one that does not tell it from a base misfit or a drift: the first gates
    for name in ("saturation", "amplifier_slew_limit", "sensor_offset"):
        assert S._ratio_max(TERMS[name], ["a term"]) == sg.RATIO_MAX, name


def test_a_small_creep_beside_what_the_first_term_left_is_named_by_its_signature():
    """A creep worth a held-out ratio of about 0.92 beside 100 nm of error left by the first term: above the first
    round's 0.8 gate, but significant, and its signature holds, so it is named in a later round (not in the
    first)."""
    ctx, fold, block, e = _setup(lambda s: _creep(s, g=0.03) + _left(s), seed=7)
    first, kept0 = _round(ctx, fold, block, e, [])
    creep = next(c for c in first if c.name == "creep")
    assert not creep.significant and max(creep.fold_ratios) > sg.RATIO_MAX and kept0 == []
    evals, kept = _round(ctx, fold, block, e, ["a term"])
    creep = next(c for c in evals if c.name == "creep")
    assert creep.below_gates and creep.p < creep.p_max
    assert kept == ["creep"], [(c.name, c.veto) for c in evals]
    assert creep.slow_signature["holds"]


def test_a_small_offset_keeps_the_first_gates():
    """A 50 nm offset beside 100 nm left by the first term (ratio about 0.9): the offset's signature (a level per
    session) is also what a drift leaves between sessions, so it is not the evidence below the gates."""
    ctx, fold, block, e = _setup(lambda s: 0.05 + _left(s), seed=7)
    evals, kept = _round(ctx, fold, block, e, ["a term"])
    off = next(c for c in evals if c.name == "sensor_offset")
    assert max(off.fold_ratios) > sg.RATIO_MAX and off.ratio_max == sg.RATIO_MAX and not off.significant
    assert "sensor_offset" not in kept


def test_a_base_misfit_after_the_first_term_is_not_named():
    """A wrong loop width, an unknown initial state and the first term's leftover: with the gates at 1 nothing
    slow is named (the base's refit takes the width, the bounded initial state the transient, and no signature
    holds)."""
    ctx, fold, block, e = _setup(lambda s: 0.04 * s.hyst + 0.05 * np.exp(-s.t / 0.3) * (s.index == 1) + _left(s),
                                 seed=5)
    evals, kept = _round(ctx, fold, block, e, ["a term"])
    assert kept == [], [(c.name, c.fold_ratios, c.p, c.veto) for c in evals]


def _cand(name, fold, credited, ratio_max, signature=None):
    return S.Candidate(term=TERMS[name], ratio=fold, fold_ratios=[fold, fold], nrmse_before=0.01,
                       nrmse_after=0.01 * fold, t=5.0, p=1e-6, n_active=20, p_max=1e-3, dbic=-10.0, n_eff=100.0,
                       significant=True, setting=[None, None], coef=[None, None], credited=credited,
                       ratio_max=ratio_max, slow_signature=signature)


def test_below_the_gates_a_slow_signature_must_hold_not_only_confirm():
    confirms = {"holds": False, "confirms": True, "alpha": sg.ALPHA / 3, "unique_ratio": 0.9, "p_value": 5e-3}
    holds = dict(confirms, holds=True, p_value=1e-4)
    below = _cand("thermal_drift", 0.9, 0.95, S.FURTHER_RATIO_MAX, confirms)
    above = _cand("thermal_drift", 0.6, 0.7, S.FURTHER_RATIO_MAX, confirms)   # within the first round's gates
    kept = _cand("creep", 0.9, 0.9, S.FURTHER_RATIO_MAX, holds)
    S._slow_beyond_gates([below, above, kept], lambda *a: None)
    assert below.below_gates and not below.significant and "must hold" in below.veto
    assert not above.below_gates and above.significant and above.veto is None
    assert kept.significant and kept.veto is None


def test_below_the_gates_a_drive_side_term_needs_a_testable_check():
    c = _cand("delay", 0.9, 0.9, S.FURTHER_RATIO_MAX)
    untestable = lambda cand: {"testable": False, "passed": True, "figures": {}, "reason": ""}
    assert S._first_exact([c], None, None, None, 1.0, lambda *a: None, untestable) is None
    assert "no informative bin" in c.veto
    c = _cand("delay", 0.9, 0.9, S.FURTHER_RATIO_MAX)
    assert S._first_exact([c], None, None, None, 1.0, lambda *a: None, None) is None
    assert "no signature check ran" in c.veto


@pytest.mark.parametrize("ratio_max", [sg.RATIO_MAX, S.FURTHER_RATIO_MAX])
def test_nothing_left_but_noise_is_not_significant_at_either_gate(ratio_max):
    ctx, fold, block, e = _setup(lambda s: _left(s), seed=9)
    c = S._evaluate([ctx, ctx], TERMS["creep"], [e, e], fold, block, ROWS, sg.ALPHA / 11, ratio_max)
    assert not c.significant
