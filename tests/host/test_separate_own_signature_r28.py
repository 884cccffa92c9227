"""Round 28: an alternative of the pair test that its own signature refuses is not inseparable
(docs/diagnose-rounds/round-28.md, "Round 28: slow effects"; ``select.own_signature_refuses``, ``select._separate``).

The pair test is linearized and physics-blind (development s140-016: a drift named, creep and a slew limit
reported inseparable while creep's step test on its dwells gave ratio 1.00, p = 1.0). Here the pair tests are
given (``separate`` replaced by a fixed answer) and the signatures synthetic: creep without its tail after the
steps and a drive-side term whose shape check fails are told apart; with a tail that holds, a shape check that
passes or no signature at all the verdict stays ``inseparable``; other verdicts are never changed.
"""

import types

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.ident.terms import TERMS

DT = 1e-4


def _cand(name, slow_signature=None):
    return S.Candidate(term=TERMS[name], ratio=0.96, fold_ratios=[0.95, 0.97], nrmse_before=0.02,
                       nrmse_after=0.019, t=3.0, p=4e-4, n_active=40, p_max=1e-3, dbic=-5.0, n_eff=500.0,
                       significant=False, setting=[1.0, 1.0], coef=[None, None], credited=1.0,
                       slow_signature=slow_signature)


def _step(p, folds):
    return {"step_response": {"p": p, "fold_ratios": list(folds), "ratio": float(np.mean(folds)), "dwells": 2}}


def _pair(name, verdict="inseparable"):
    t = {"p": 1e-4, "fold_ratios": [0.96, 0.97], "n_active": 40, "significant": True}
    return {"name": name, "verdict": verdict, "named_alone": t, "alternative_alone": t,
            "named_beyond": {**t, "p": 1.0, "significant": False},
            "alternative_beyond": {**t, "p": 0.03, "significant": False}}


def _run(monkeypatch, named, evals, pairs, check=None):
    monkeypatch.setattr(S, "separate", lambda *a, **k: [dict(r) for r in pairs])
    fctx = [types.SimpleNamespace(valid=[np.ones(4, bool)], dt=DT, design_cache={})] * 2
    S._separate(named, evals, fctx, [np.zeros(4)] * 2, np.zeros(4, int), np.zeros(4, int), 10, lambda *a: None,
                check)
    return {r["name"]: r["verdict"] for r in named.separation}


def test_creep_without_its_tail_after_the_steps_is_no_alternative():
    c = _cand("creep", _step(1.0, (1.0, 1.0)))
    why = S.own_signature_refuses(c)
    assert why is not None and "tail after the steps" in why


def test_creep_whose_tail_holds_at_its_own_level_stays_an_alternative():
    assert S.own_signature_refuses(_cand("creep", _step(1e-4, (0.4, 0.5)))) is None
    # significant but the held-out error rises in a fold: the tail does not hold
    assert S.own_signature_refuses(_cand("creep", _step(1e-4, (0.4, 1.02)))) is not None


def test_creep_without_slow_signatures_is_left_to_the_pair_test():
    assert S.own_signature_refuses(_cand("creep")) is None


def test_a_drive_side_alternative_is_judged_by_its_shape_check():
    r = _cand("amplifier_slew_limit")
    assert S.own_signature_refuses(r) is None   # no check in this round: nothing to say
    assert S.own_signature_refuses(r, lambda c: None) is None
    assert S.own_signature_refuses(r, lambda c: {"passed": True, "reason": None}) is None
    why = S.own_signature_refuses(r, lambda c: {"passed": False, "reason": "present below the limit"})
    assert why is not None and "present below the limit" in why


def test_separate_tells_apart_only_inseparable_alternatives_its_signature_refuses(monkeypatch):
    d = _cand("thermal_drift")
    d.significant = True
    creep = _cand("creep", _step(1.0, (1.0, 1.0)))
    slew = _cand("amplifier_slew_limit")
    delay = _cand("delay")
    evals = [d, creep, slew, delay]
    fails = lambda c: {"passed": c.name != "amplifier_slew_limit", "reason": "present below the limit"}
    got = _run(monkeypatch, d, evals, [_pair("creep"), _pair("amplifier_slew_limit"), _pair("delay", "both")],
               fails)
    assert got == {"creep": "signature", "amplifier_slew_limit": "signature", "delay": "both"}
    assert "tail after the steps" in d.separation[0]["reason"]
    # a shape check that passes and a creep tail that holds leave the pair inseparable
    creep.slow_signature = _step(1e-4, (0.4, 0.5))
    got = _run(monkeypatch, d, evals, [_pair("creep"), _pair("amplifier_slew_limit")],
               lambda c: {"passed": True, "reason": None})
    assert got == {"creep": "inseparable", "amplifier_slew_limit": "inseparable"}


def test_a_told_apart_alternative_is_not_written_as_inseparable():
    from piezoctl.diagnose.discriminate import separation_doc
    sep = [_pair("creep"), _pair("amplifier_slew_limit")]
    sep[0].update(verdict="signature", reason="its own signature, the tail after the steps, does not hold")
    fields, text = separation_doc("thermal_drift", sep)
    assert [a["name"] for a in fields["alternatives"]] == ["amplifier_slew_limit"]
    assert "creep" not in text
