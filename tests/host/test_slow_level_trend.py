"""Round 15: a drift told from a sensor offset by the level's trend within the reveal recordings, on the scale
each recording shows itself (slow_signature.level_trend_test and the attribution's use of it)."""

import numpy as np

from piezoctl.diagnose.discriminate import separation_doc
from piezoctl.diagnose.slow_signature import attribute, level_trend_test, trend_phrase
from test_diagnose_slow import _cand, _ctx, _run, _test
from test_slow_signature_levels import _misfit

WALK_OFF_UM = 0.5   # the middle recording's level misfit: a history of another kind than the calibration's


def _wander(s, um=0.01, period_s=3.7):
    """The base's misfit moving a recording's level from block to block (its history's), plus the level the whole
    recording sits off by (the middle one, like a reveal walk on a Coleman-Hodgdon law)."""
    return um * np.sin(2 * np.pi * s.t / period_s + s.index) + (WALK_OFF_UM if s.index == 1 else 0.0)


def _warmup(s, total=0.3, t_end=92.0):
    """A drift still moving through the reveal: `total` um over the session, continuous across recordings."""
    return total * (s.t_session + s.t) / t_end


def test_a_drift_moving_within_the_recordings_trends_whatever_one_recording_sits_off_by():
    rng = np.random.default_rng(21)
    ctx = _ctx(rng)
    _misfit(ctx)
    tests = _run(ctx, lambda s: _warmup(s) + _wander(s), rng)
    tr = tests["thermal_drift"].trend
    assert tr is not None and tests["sensor_offset"].trend == tr and tr["recordings"] == [0, 1, 2]
    assert tr["trends"], tr
    assert abs(tr["slope_um_per_s"] - 0.3 / 92.0) < 3 * tr["se_um_per_s"] + 0.2 * 0.3 / 92.0, tr


def test_an_offset_whose_recordings_sit_at_different_levels_does_not_trend_and_excludes_a_drift():
    """The walk's 0.5 um is what round 12's spread called a drift (F against s_L); the trend does not."""
    rng = np.random.default_rng(22)
    ctx = _ctx(rng)
    _misfit(ctx)
    tests = _run(ctx, lambda s: 0.4 + _wander(s), rng)
    tr = tests["sensor_offset"].trend
    assert tests["sensor_offset"].spread["varies"]           # the levels between the recordings vary ...
    assert not tr["trends"] and tr["p"] > 0.01, tr            # ... but the level does not move within them
    assert tr["excludes_drift"], tr                           # nor at the rate a drift to that level would need
    assert len(tr["needed_um_per_s"]) == 1 and tr["needed_um_per_s"][0] > 10 * tr["se_um_per_s"]


def test_levels_that_wander_too_much_cannot_exclude_a_drift_and_the_pair_is_reported():
    rng = np.random.default_rng(23)
    ctx = _ctx(rng)
    _misfit(ctx)
    tests = _run(ctx, lambda s: 0.1 + _wander(s, um=0.08, period_s=2.3), rng)
    tr = tests["sensor_offset"].trend
    assert not tr["trends"] and tr["excludes_drift"] is False, tr
    evals = [_cand("sensor_offset", True, 0.5), _cand("thermal_drift", False, 0.95), _cand("creep", False, 1.0)]
    off = tests["sensor_offset"]
    off.holds, off.level = True, None
    text = attribute(evals, [_test("creep", False, 1.0), tests["thermal_drift"], off])
    assert evals[0].name == "sensor_offset" and evals[0].significant, text
    assert evals[0].slow_alternative["name"] == "thermal_drift" and "cannot be excluded" in text
    fields, sentence = separation_doc("sensor_offset", [{"name": "thermal_drift", "verdict": "inseparable",
                                                         "reason": evals[0].slow_alternative["reason"]}])
    assert [a["name"] for a in fields["alternatives"]] == ["thermal_drift"] and "cannot tell" in sentence


def _trend(trends, excludes=True):
    return {"recordings": [0, 1, 2], "slopes_um_per_s": [1e-3] * 3, "slope_um_per_s": 1e-3 if trends else 0.0,
            "se_um_per_s": 1e-4, "t": 10.0 if trends else 0.0, "dof": 30, "p": 1e-9 if trends else 1.0,
            "trends": trends, "levels_um": [0.1], "needed_um_per_s": [2e-3], "quantile": 2.75,
            "excludes_drift": excludes}


def test_a_trending_drift_takes_the_level_the_offset_took_and_a_spread_alone_does_not():
    # s113-047-like: the offset passed and its signature holds; the drift's within the recordings does not, nor is
    # its candidate sized (0.90/0.92), but the level trends within the recordings: the drift, with the offset's level
    evals = [_cand("sensor_offset", True, 0.67), _cand("thermal_drift", False, 0.9, p=2.9e-4), _cand("creep", False, 1.0)]
    drift, off = _test("thermal_drift", False, 1.0), _test("sensor_offset", True, 0.85)
    drift.trend = off.trend = _trend(True)
    text = attribute(evals, [_test("creep", False, 1.0), drift, off])
    assert evals[0].name == "thermal_drift" and evals[0].significant, text
    assert "own scale" in text and not getattr(evals[0], "slow_alternative", None)
    # no trend, the drift excluded: the offset alone
    evals = [_cand("sensor_offset", True, 0.67), _cand("thermal_drift", False, 0.9, p=2.9e-4), _cand("creep", False, 1.0)]
    drift, off = _test("thermal_drift", False, 1.0), _test("sensor_offset", True, 0.85)
    drift.trend = off.trend = _trend(False)
    attribute(evals, [_test("creep", False, 1.0), drift, off])
    assert evals[0].name == "sensor_offset" and evals[0].significant
    assert not getattr(evals[0], "slow_alternative", None)


def test_no_trend_test_on_the_calibrations_session_alone():
    rng = np.random.default_rng(24)
    ctx = _ctx(rng, sessions_known=False)
    ctx.offset_group, ctx.offset_sessions = [-1, -1, -1], []
    rec = np.zeros(10, int)
    assert level_trend_test([None, None], [None, None], np.zeros(10, int), np.zeros(10, int), rec, ctx, 100) is None


def test_a_trend_back_towards_the_calibrations_zero_does_not_take_the_offsets_level():
    # round 17, development s118-002 (offset -0.78 um, KP): the level trends +0.5 nm/s, back towards the
    # calibration's zero; a warm-up since the calibration moves on in the direction of the level it reached
    rng = np.random.default_rng(25)
    ctx = _ctx(rng)
    _misfit(ctx)
    tr = _run(ctx, lambda s: -0.8 + _warmup(s) + _wander(s), rng)["sensor_offset"].trend
    assert tr["trends"] and tr["levels_um"][0] < 0 < tr["slope_um_per_s"] and tr["against_level"], tr
    assert "back towards the calibration's zero" in trend_phrase(tr)
    same = _run(ctx, lambda s: 0.8 + _warmup(s) + _wander(s), rng)["sensor_offset"].trend
    assert same["trends"] and not same["against_level"], same       # away from zero: a warm-up may have left it
    for against, named in ((True, "sensor_offset"), (False, "thermal_drift")):
        evals = [_cand("sensor_offset", True, 0.67), _cand("thermal_drift", False, 0.9, p=2.9e-4),
                 _cand("creep", False, 1.0)]
        drift, off = _test("thermal_drift", False, 1.0), _test("sensor_offset", True, 0.85)
        drift.trend = off.trend = dict(_trend(True), slope_um_per_s=-1e-3 if against else 1e-3, against_level=against)
        text = attribute(evals, [_test("creep", False, 1.0), drift, off])
        assert evals[0].name == named and evals[0].significant, text
