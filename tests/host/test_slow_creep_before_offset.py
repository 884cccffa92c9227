"""Round 14: a holding creep goes before the sensor offset in the slow attribution, as a holding drift does
(slow_signature._precedence): the level a creep leaves in each recording is the offset's column's."""

import types

from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.slow_signature import ALPHA_SIGNATURE, SignatureTest, _precedence, attribute


def _cand(name, significant, ratio, p=1e-6):
    return types.SimpleNamespace(name=name, significant=significant, veto=None, fold_ratios=[ratio, ratio],
                                 credited=ratio, dbic=-10.0, p=p, discrimination=None, slow_signature=None)


def _test(name, ratio, p):
    return SignatureTest(name=name, unique_ratio=ratio, fold_ratios=[ratio, ratio], credited=ratio, p=p,
                         n_active=20, holds=p < ALPHA_SIGNATURE, confirms=p < sg.ALPHA)


def test_holding_creep_goes_before_the_offset_whatever_the_unique_ratios():
    """s112-030's figures: the offset's unique ratio 0.18 below creep's 0.33, both holding."""
    tests = [_test("creep", 0.33, 5.9e-4), _test("thermal_drift", 1.06, 0.65), _test("sensor_offset", 0.18, 1e-7)]
    assert _precedence(tests, {"creep"}) == ["creep", "sensor_offset"]
    evals = [_cand("sensor_offset", True, 0.45, p=2.4e-2), _cand("creep", True, 0.62, p=4.8e-9),
             _cand("thermal_drift", False, 1.1, p=1.0)]
    text = attribute(evals, tests)
    assert evals[0].name == "creep" and evals[0].significant and "creep" in text
    off = next(c for c in evals if c.name == "sensor_offset")
    assert not off.significant and "attributed to creep" in off.veto


def test_offset_first_when_creep_does_not_hold():
    """Without creep's signature (no tail after the steps) the order is as before: the offset."""
    tests = [_test("creep", 0.33, 0.2), _test("thermal_drift", 1.06, 0.65), _test("sensor_offset", 0.18, 1e-7)]
    assert _precedence(tests, {"creep"}) == ["sensor_offset"]
    evals = [_cand("sensor_offset", True, 0.45), _cand("creep", True, 0.62), _cand("thermal_drift", False, 1.1)]
    attribute(evals, tests)
    assert evals[0].name == "sensor_offset" and evals[0].significant
    assert not next(c for c in evals if c.name == "creep").significant


def test_drift_and_creep_both_before_the_offset_in_their_own_order():
    tests = [_test("creep", 0.5, 1e-5), _test("thermal_drift", 0.4, 1e-5), _test("sensor_offset", 0.2, 1e-7)]
    assert _precedence(tests, set()) == ["thermal_drift", "creep", "sensor_offset"]
