"""Round 20: a drift against an offset, and after a first term (slow_signature.against_reached, _trend_is_drifts).

The figures are development cases' (docs/diagnose-rounds/round-20.md, "Round 20: drift"): s123-016 (the drift refused for a trend
"back towards zero" against a level the walk's history misfit set), s123-047 (the drift's candidate refused by its
credited ratio alone while the level trends within the recordings), s118-001 (after the slew, the drift's joint
test sees nothing, the trend does)."""

import types

from piezoctl.diagnose import select
from piezoctl.diagnose.slow_signature import against_reached, attribute
from test_diagnose_slow import _test


def _trend(slope, se, levels, against, pair_level=None):
    return {"trends": True, "t": slope / se, "slope_um_per_s": slope, "se_um_per_s": se, "dof": 56, "p": 1e-10,
            "recordings": [0, 1, 2], "levels_um": levels, "needed_um_per_s": [levels[0] / 60.0], "quantile": 2.9,
            "excludes_drift": True, "against_level": against, "same_shape": [], "pair_level": pair_level}


def _level(offset_um, within):
    return {"p": 0.2, "fold_ratios": [0.98, 0.99], "n_active": 31, "depends_on_level": False,
            "offset_um": [offset_um], "base_level_rms_um": 0.0056, "histories": 20, "quantile": 2.86,
            "within_base_misfit": within, "refused": within}


def test_the_trend_is_judged_against_the_offsets_level_not_the_recordings_mean():
    """s123-016: the recordings' mean level -0.072 um (the walk at -0.415 um) made +2.92 nm/s "against" it; the
    offset's candidate took +0.207 um, beyond the base's misfit: the trend goes the way of that level."""
    tr = _trend(0.00292, 0.00033, [-0.072], True)
    out = against_reached(tr, _level(0.207, False))
    assert out["against_level"] is False and out["reached_from"] == "offset" and out["reached_um"] == [0.207]


def test_a_trend_against_an_established_offset_is_still_against():
    """Round 17's case s118-002 (offset -0.78 um, trend +0.49 +- 0.11 nm/s) stays refused as a drift."""
    out = against_reached(_trend(0.00049, 0.00011, [-0.78], True), _level(-0.78, False))
    assert out["against_level"] is True and out["reached_from"] == "offset"


def test_no_level_beyond_the_base_misfit_sets_no_direction():
    """s118-001 after the slew: the offset's level -0.026 um lies within the base's misfit and no pair's common
    level lies beyond it, so no level is established for the trend to go against."""
    pl = {"levels_um": [0.267], "holds": False}
    out = against_reached(_trend(-0.00139, 0.00031, [0.41], True, pl), _level(-0.026, True))
    assert out["against_level"] is False and out["reached_um"] == [] and out["reached_from"] is None
    # the pair's common level counts when it lies beyond that misfit
    pl = {"levels_um": [0.267], "holds": True}
    out = against_reached(_trend(-0.00139, 0.00031, [0.41], True, pl), _level(-0.026, True))
    assert out["against_level"] is True and out["reached_from"] == "pair"


def _cand(name, significant, folds, credited, p, below_gates=False, veto=None, credited_only=False):
    return types.SimpleNamespace(name=name, significant=significant, veto=veto, fold_ratios=list(folds),
                                 credited=credited, dbic=-60.0, p=p, discrimination=None, slow_signature=None,
                                 below_gates=below_gates, credited_only=credited_only)


def _named(evals):
    return [c.name for c in evals if c.significant and not c.veto]


def _after_slew(creep_holds):
    """s118-001's second round: the drift's candidate significant below the gates (0.89/0.95, credited 1.00), the
    offset's (0.64/0.66) with its level within the base's misfit; no joint signature holds, the level trends."""
    evals = [_cand("thermal_drift", True, (0.89, 0.95), 1.00, 3.6e-4, below_gates=True),
             _cand("sensor_offset", True, (0.64, 0.66), 0.71, 4.5e-10, below_gates=True),
             _cand("creep", False, (1.00, 0.97), 1.00, 4.6e-3, below_gates=True)]
    creep = _test("creep", creep_holds, 1.00)
    drift, off = _test("thermal_drift", False, 0.99, p=0.03), _test("sensor_offset", False, 1.01)
    off.level = _level(-0.026, True)
    drift.trend = off.trend = _trend(-0.00139, 0.00031, [0.41], False)
    return evals, [creep, drift, off]


def test_after_a_first_term_the_drifts_trend_is_its_signature():
    evals, tests = _after_slew(creep_holds=False)
    text = attribute(evals, tests)
    select._slow_beyond_gates(evals, lambda *a: None)
    assert _named(evals) == ["thermal_drift"], text
    assert evals[0].slow_signature["trend_holds"] is True


def test_after_a_first_term_a_trend_beside_creeps_signature_is_not_the_drifts():
    """Creep relaxing after the drive's changes moves the level within a recording too (round 19's s117-004)."""
    evals, tests = _after_slew(creep_holds=True)
    attribute(evals, tests)
    select._slow_beyond_gates(evals, lambda *a: None)
    assert "thermal_drift" not in _named(evals)


def _first_round(credited_only):
    """s123-047's first round: the offset's candidate passed (0.32/0.35), the drift's was refused by its credited
    ratio alone (0.65/0.71, credited 0.88); the offset's joint signature holds, the drift's does not, the level
    trends +2.81 +- 0.31 nm/s the way of the offset's +0.146 um."""
    veto = "its held-out improvement lies within what the base's error ... explains"
    evals = [_cand("sensor_offset", True, (0.32, 0.35), 0.40, 1.7e-13),
             _cand("thermal_drift", False, (0.65, 0.71), 0.88, 2.7e-5, veto=veto, credited_only=credited_only),
             _cand("creep", False, (0.99, 0.98), 1.02, 1.0)]
    creep, drift, off = _test("creep", False, 1.00), _test("thermal_drift", False, 1.01, p=0.04), \
        _test("sensor_offset", True, 0.38)
    off.level = _level(0.146, False)
    drift.trend = off.trend = _trend(0.00281, 0.00031, [0.236], False)
    return evals, [creep, drift, off]


def test_a_drift_refused_by_its_credit_alone_takes_the_offsets_level_when_the_level_trends():
    evals, tests = _first_round(credited_only=True)
    text = attribute(evals, tests)
    assert _named(evals) == ["thermal_drift"], text
    assert "attributed to thermal_drift" in next(c for c in evals if c.name == "sensor_offset").veto


def test_a_drift_refused_for_another_reason_does_not():
    evals, tests = _first_round(credited_only=False)
    attribute(evals, tests)
    assert _named(evals) == ["sensor_offset"]
