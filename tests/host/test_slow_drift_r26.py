"""Round 26: a significant drift whose line fitted on every block the exact check refuses is checked again sized on
a repeated drive's cycles (slow_signature.drift_on_cycles -> Candidate.cycle_coef, select._exact_on_cycles;
docs/diagnose-rounds/round-26.md, "Round 26: slow effects")."""

import types

import numpy as np

from piezoctl.diagnose import select as sel
from piezoctl.diagnose import slow_signature as ss
from test_slow_drift_r25 import HELD

SIZED = ((np.inf, -1.0), np.array([0.1, 0.0, 0.0074]))


def _significant():
    return types.SimpleNamespace(name="thermal_drift", significant=True, veto=None, fold_ratios=[0.76, 0.65],
                                 credited=0.74, dbic=-88.0, p=1.3e-4, p_max=1.1e-3, discrimination=None,
                                 credited_only=False, setting=[(150.0, 1.0)] * 2, coef=[np.zeros(4)] * 2,
                                 cycle_coef=None, from_cycles=False)


def test_a_significant_candidate_keeps_its_line_and_gets_the_cycles_model(monkeypatch):
    monkeypatch.setattr(ss, "cycle_mean_test", lambda *a: HELD)
    monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a: SIZED)
    c = _significant()
    ss.drift_on_cycles([c], [None, None], [None, None], np.zeros(1), lambda *a: None)
    assert c.significant and c.veto is None and not c.from_cycles   # its own model is checked first
    assert c.setting == [(150.0, 1.0)] * 2 and c.cycle_coef == [SIZED, SIZED]
    # cycles dying out, a rate against their sign, or a vetoed candidate: no cycles model
    for cy, sized, veto in (({**HELD, "persists": False}, SIZED, None), (HELD, ((np.inf, 1.0), SIZED[1]), None),
                            (HELD, SIZED, "refused")):
        monkeypatch.setattr(ss, "cycle_mean_test", lambda *a, _c=cy: _c)
        monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a, _s=sized: _s)
        c = _significant()
        c.veto = veto
        ss.drift_on_cycles([c], [None, None], [None, None], np.zeros(1), lambda *a: None)
        assert c.cycle_coef is None


def _exact(after):
    return {"params": {}, "sse_before": 1.0, "sse_after": after, "n": 100, "ys": [], "per_recording": [(1.0, after)]}


def _refused():
    c = _significant()
    c.cycle_coef = [SIZED, SIZED]
    c.exact_fold_ratios = [1.22, 1.22]
    c.veto = "the exact simulation of the refined model with this term does not lower the held-out error"
    c.exact = None
    c.term = types.SimpleNamespace(ratio_beyond_level=False)
    return c


def test_the_cycles_model_replaces_the_refused_line_only_when_it_lowers_each_fold(monkeypatch):
    monkeypatch.setattr(sel.dataclasses, "replace", lambda c, **kw: types.SimpleNamespace(**{**vars(c), **kw}))
    monkeypatch.setattr(sel, "_add_note", lambda c, note: None)
    ctx = types.SimpleNamespace(names=["a"])
    seen = []

    def fold(ctx_, c, f, fold_all, recs):
        seen.append((c.setting[f], c.coef[f]))
        return _exact(0.64)
    monkeypatch.setattr(sel, "_exact_fold", fold)
    c = _refused()
    assert sel._exact_on_cycles(c, [ctx, ctx], np.zeros(1), [], 1.0, lambda *a: None)
    assert seen == [SIZED, SIZED]   # the cycles' setting and coefficients, per fold
    assert c.veto is None and c.from_cycles and c.setting == [SIZED[0]] * 2 and c.coef[0] is SIZED[1]
    assert np.allclose(c.exact_fold_ratios, [0.8, 0.8])
    # a fold not lowered: still refused, and the reason says so
    monkeypatch.setattr(sel, "_exact_fold", lambda ctx_, c, f, *a: _exact(0.64 if f == 0 else 1.1))
    c = _refused()
    assert not sel._exact_on_cycles(c, [ctx, ctx], np.zeros(1), [], 1.0, lambda *a: None)
    assert not c.from_cycles and "nor sized on the repeated drive's cycles" in c.veto
    assert c.setting == [(150.0, 1.0)] * 2
