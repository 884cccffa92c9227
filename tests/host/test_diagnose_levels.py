"""Levels per recording in the diagnosis: the sensor's zero per session, the unknown initial state."""

import numpy as np
import pytest

from piezoctl.diagnose.run import _offset_groups
from piezoctl.diagnose.select import _fit_predict
from piezoctl.io.recording import sensor_session
from piezoctl.models.hysteresis import initial_state_span


class _Rec:
    def __init__(self, session=None):
        self.meta = {} if session is None else {"session": session}


def test_offset_groups_one_column_per_session_other_than_the_calibrations():
    cal = [_Rec("A"), _Rec("A")]
    recs = [_Rec("B"), _Rec("C"), _Rec("B"), _Rec("A")]
    g = _offset_groups(cal, recs)
    assert g["offset_sessions"] == ["B", "C"]
    assert g["offset_group"] == [0, 1, 0, -1]   # the calibration's session keeps the base's zero


def test_offset_groups_need_every_recording_labelled():
    assert _offset_groups([_Rec("A")], [_Rec("B"), _Rec()]) == {}
    assert _offset_groups([_Rec()], [_Rec("B")]) == {}
    assert sensor_session(_Rec("  ")) is None and sensor_session(_Rec(" 2 ")) == "2"


def _plane():
    # reversible part plus two plays with increasing F_j: a Preisach density of one sign
    return {"type": "plane", "r": [0.0, 0.2, 0.5], "knots": [[-1.5, 1.5]] * 3,
            "values": [[-3.0, 3.0], [-1.0, 1.0], [-2.0, 2.0]], "v_rest": 0.0}


def test_initial_state_span_is_positive_until_the_drive_wipes_it():
    hp = _plane()
    up = np.linspace(0.1, 0.6, 50)        # a drive that has not yet visited either end
    sweep = np.concatenate([up, np.linspace(0.6, 1.0, 40), np.linspace(1.0, -1.0, 200), np.linspace(-1.0, 0.3, 100)])
    d = initial_state_span(hp, sweep, -1.0, 1.0)
    assert np.all(d[:50] > 0.1)           # the two histories disagree by the plays' memory
    assert np.allclose(d[290:], 0.0)      # after both ends were visited nothing of the start is left
    assert np.all(d >= -1e-12)


def test_bounded_nuisance_gain_stays_within_one():
    rng = np.random.default_rng(1)
    n = 400
    N = np.linspace(1.0, 0.0, n)[:, None]        # an initial-state column
    X = rng.normal(size=(n, 1))
    e = 5.0 * N[:, 0] + 0.3 * X[:, 0]             # a level far beyond what the initial state can explain
    train = np.arange(n) % 2 == 0
    test = ~train
    idx = np.flatnonzero(train)
    th, _, _ = _fit_predict(X, e, train, test, rows=n, nuis=(N[idx], N[test], (np.array([-1.0]), np.array([1.0]))))
    assert th[0] == pytest.approx(1.0)            # clipped at the bound: the rest stays for the term to explain
    th_free, _, _ = _fit_predict(X, e, train, test, rows=n, nuis=(N[idx], N[test]))
    assert th_free[0] == pytest.approx(5.0, rel=0.05)


def test_a_term_that_breaks_one_recording_is_flagged():
    from piezoctl.diagnose import significance as sg
    from piezoctl.diagnose.select import _worsened
    # per fold, per recording: (sse before, sse after) on the held-out samples
    fine = [{"per_recording": [(4.0, 1.0), (1.0, 1.1)]}, {"per_recording": [(4.0, 1.0), (1.0, 1.0)]}]
    assert _worsened(fine, ["walk", "triangle"]) is None
    broken = [{"per_recording": [(4.0, 0.5), (1.0, 4.0)]}, {"per_recording": [(4.0, 0.5), (1.0, 4.0)]}]
    name, k = _worsened(broken, ["walk", "triangle"])
    assert name == "triangle" and k == pytest.approx(2.0) and k > sg.WORSEN_MAX


def test_a_sensor_curve_that_breaks_one_recording_is_vetoed_a_history_dependent_term_is_not():
    # round 17 (null s117-018): the sensor's curve is one map of the reading on every recording; a history-dependent
    # term (creep, rate) may leave one recording worse and is named with the caution only
    import types
    from piezoctl.diagnose import select as S
    from piezoctl.ident.terms import TERMS
    fctx = [types.SimpleNamespace(names=["walk", "triangle"])] * 2

    def cand(name, per):
        c = S.Candidate(term=TERMS[name], ratio=0.6, fold_ratios=[0.6, 0.6], nrmse_before=0.02, nrmse_after=0.012,
                        t=5.0, p=1e-9, n_active=40, p_max=1e-3, dbic=-50.0, n_eff=500.0, significant=True,
                        setting=[None, None], coef=[None, None], credited=0.6)
        c.exact = [{"sse_before": sum(b for b, _ in per), "sse_after": sum(a for _, a in per), "n": 100,
                    "per_recording": per, "params": {}} for _ in (0, 1)]
        return c

    broken = [(4.0, 1.0), (0.1, 0.5)]      # the walk 2x better, the triangle x2.24 worse; in all 0.73
    fine = [(4.0, 1.0), (0.1, 0.11)]
    c = cand("sensor_nonlinearity", broken)
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is None
    assert "the same on every recording" in c.veto and "triangle" in c.veto
    c = cand("sensor_nonlinearity", fine)
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is c and c.worsened is None
    c = cand("creep", broken)
    assert S._first_exact([c], fctx, None, None, 1.0, lambda *a: None) is c
    assert c.veto is None and c.worsened[0] == "triangle"
