"""Round 21: a level that stopped moving before the reveal is the offset's, not a drift's
(slow_signature.settled_fraction; the round-12 rule in attribute).

The figures are development case s126-017's (docs/diagnose-rounds/round-21.md, "Round 21: drift"): a sensor offset of +0.44 um
(Maxwell slip) named ``thermal_drift`` by round 12's rule, the level trending +0.13 +- 0.02 nm/s within the
recordings (t = 5.6), 0.007 of the steady rate that would have reached it."""

import numpy as np

from piezoctl.diagnose.slow_signature import SETTLED_FRACTION, against_reached, attribute, settled_fraction
from test_diagnose_slow import _test
from test_slow_drift_r20 import _cand, _level, _named


def _warm_up(a, tau, t_c):
    """Level [um] and rate [um/s] of a warm-up a (1 - exp(-t/tau)) at t_c [s] after its start."""
    return a * (1.0 - np.exp(-t_c / tau)), a / tau * np.exp(-t_c / tau)


def test_the_settled_fraction_is_the_warm_ups_law_whatever_its_size():
    for a, tau, t_c in ((0.3, 20.0, 40.0), (-0.5, 80.0, 30.0), (0.05, 200.0, 25.0), (1.0, 8.0, 40.0)):
        c, b = _warm_up(a, tau, t_c)
        x = t_c / tau
        assert np.isclose(settled_fraction(b, c, t_c), x / np.expm1(x))
    # three time constants on: 95 % of the change done
    assert np.isclose(SETTLED_FRACTION, 3.0 / np.expm1(3.0))
    assert settled_fraction(1e-3, 0.0, 20.0) == np.inf   # no level: nothing settled


def _trend_of(b, se, c, t_c):
    return {"trends": True, "t": b / se, "slope_um_per_s": b, "se_um_per_s": se, "dof": 45, "p": 1e-6,
            "recordings": [0, 1, 2], "levels_um": [c], "needed_um_per_s": [c / t_c], "t_c_s": [t_c],
            "quantile": 2.9, "excludes_drift": True, "against_level": False, "same_shape": [], "pair_level": None}


def test_a_warm_up_two_time_constants_on_is_not_settled_one_four_on_is():
    for x, settled in ((1.0, False), (2.0, False), (4.0, True), (6.0, True)):
        c, b = _warm_up(0.4, 25.0 / x, 25.0)
        out = against_reached(_trend_of(b, 0.1 * b, c, 25.0), _level(c, False))
        assert out["settled"] is settled and out["against_level"] is False, (x, out)
    # no level established: nothing to be settled against
    out = against_reached(_trend_of(1e-5, 1e-6, 0.4, 25.0), _level(0.4, True))
    assert out["settled"] is False and out["reached_um"] == []


def _offset_with_trend(b):
    """s126-017's first round: the offset's candidate passed and its joint signature holds (unique 0.05), the
    drift's own candidate beyond it gains nothing (1.04/1.00, p 1.0), the level trends at ``b`` [um/s]."""
    evals = [_cand("sensor_offset", True, (0.06, 0.05), 0.05, 1.1e-12),
             _cand("thermal_drift", False, (1.04, 1.00), 1.01, 1.0),
             _cand("creep", False, (1.01, 1.00), 1.00, 1.0)]
    creep, drift, off = _test("creep", False, 1.00), _test("thermal_drift", False, 1.01), \
        _test("sensor_offset", True, 0.05)
    off.level = _level(0.436, False)
    tr = _trend_of(b, 0.15 * abs(b), 0.436, 24.8)
    tr.update(against_reached(tr, off.level))
    drift.trend = off.trend = tr
    return evals, [creep, drift, off]


def test_a_settled_level_with_a_small_trend_is_the_offsets():
    evals, tests = _offset_with_trend(0.00013)
    text = attribute(evals, tests)
    assert _named(evals) == ["sensor_offset"], text
    assert "stopped before the reveal" in text


def test_a_level_still_moving_at_half_the_steady_rate_is_still_the_drifts():
    """Round 12's rule is unchanged where the warm-up has not settled (0.5 of the steady rate: about one time
    constant on)."""
    evals, tests = _offset_with_trend(0.5 * 0.436 / 24.8)
    text = attribute(evals, tests)
    assert _named(evals) == ["thermal_drift"], text
