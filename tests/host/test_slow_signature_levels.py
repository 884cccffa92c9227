"""Round 12: a drift told from a sensor offset by the levels of a session's recordings (slow_signature.py,
``level_spread_test`` and the attribution's use of it)."""

import types

import numpy as np
import pytest

from piezoctl.diagnose.slow_signature import (ALPHA_SIGNATURE, SignatureTest, attribute, level_spread_test)
from test_diagnose_slow import _cand, _ctx, _run, _test

S_L = 0.02   # the base's level misfit on held-out calibration histories [um RMS] the tests assume


def _misfit(ctx, s_l=S_L, h=16):
    ctx.misfit = {"slow_hz": 1.0, "histories": [f"h{i}" for i in range(h)],
                  "mse_um2": {"level": s_l ** 2, "slow": 0.0, "fast": 0.0}}


def _ramp(s, total=0.3, t_end=92.0):
    """A drift on the session clock, continuous across the recordings: `total` um over the session."""
    return total * (s.t_session + s.t) / t_end


@pytest.mark.parametrize("effect,varies", [
    (_ramp, True),                                                   # levels follow the clock
    (lambda s: np.full(s.t.size, 0.2), False),                       # one sensor zero for the session
    (lambda s: np.full(s.t.size, 0.2 + 0.5 * S_L * (s.index - 1)), False),   # plus level errors within the misfit
])
def test_level_spread_tells_a_drift_from_an_offset(effect, varies):
    rng = np.random.default_rng(7)
    ctx = _ctx(rng)
    _misfit(ctx)
    tests = _run(ctx, effect, rng)
    sp = tests["sensor_offset"].spread
    assert sp is not None and sp["dof"] == 2 and sp["histories"] == 16
    assert sp["varies"] is varies, sp
    assert tests["thermal_drift"].spread == sp
    if varies:   # 0.3 um over 92 s: the three recordings' levels 40 s apart differ by about 0.13 um
        assert sp["levels_um"][0] < sp["levels_um"][1] < sp["levels_um"][2]


def test_no_level_spread_without_sessions_or_misfit():
    """One constant per recording (sessions unknown) has nothing to compare; without the base's misfit there is
    no scale: the test is not made, and nothing changes from round 11."""
    rng = np.random.default_rng(8)
    ctx = _ctx(rng, sessions_known=False)
    _misfit(ctx)
    assert _run(ctx, _ramp, rng)["sensor_offset"].spread is None
    ctx = _ctx(rng)
    assert _run(ctx, _ramp, rng)["sensor_offset"].spread is None


def test_level_spread_false_alarm_rate_is_its_level():
    """Levels that scatter only by the base's misfit (normal, RMS s_L) are said to vary at about the test's level
    (the F test is exact for normal levels and an s_L estimated from H squares; here s_L is known, so below it)."""
    rng = np.random.default_rng(9)
    n_rec, n = 4, 200
    rec = np.repeat(np.arange(n_rec), n)
    fold = np.tile(np.arange(n) % 2, n_rec)
    ctx = types.SimpleNamespace(offset_group=[0] * n_rec, n_rec=n_rec, offset_of=lambda i: 0)
    _misfit(ctx)
    design = (np.zeros((rec.size, 0)), np.zeros(0), np.zeros(0), {})
    hits, trials = 0, 2000
    for _ in range(trials):
        e = np.repeat(rng.normal(0.0, S_L, n_rec), n) + 0.001 * rng.normal(size=rec.size)
        hits += level_spread_test([design, design], [e, e], fold, rec, ctx, rows=10 ** 6)["varies"]
    assert hits / trials < 3 * ALPHA_SIGNATURE, hits
    # and a spread of 4 s_L between four recordings is found
    e = np.repeat(4 * S_L * np.array([-1.5, -0.5, 0.5, 1.5]), n)
    assert level_spread_test([design, design], [e, e], fold, rec, ctx, rows=10 ** 6)["varies"]


def _spread(varies):
    return {"levels_um": [0.0, 0.1, 0.2], "sessions_tested": [0], "dof": 2, "spread_rms_um": 0.1,
            "base_level_rms_um": S_L, "histories": 16, "f": 25.0 if varies else 1.0, "p": 1e-5 if varies else 0.4,
            "varies": varies}


def _with_spread(t, varies):
    t.spread = _spread(varies)
    return t


def test_attribute_names_the_sized_drift_whose_level_trends_not_whose_session_levels_vary():
    # s108-001-like: the offset passed and its signature holds, the drift's within the recordings does not, the
    # recordings' levels vary beyond the base's misfit and the drift's candidate has the size. Round 12 named the
    # drift on the spread; round 15 (test_slow_level_trend.py): the spread carries each history's misfit, so it
    # names the drift only when the level trends within the recordings on their own scale
    def tests_with(trends):
        drift, off = _with_spread(_test("thermal_drift", False, 0.8), True), _with_spread(_test("sensor_offset", True, 0.5), True)
        drift.trend = off.trend = {"trends": trends, "slope_um_per_s": 2e-3, "se_um_per_s": 2e-4, "t": 10.0 if trends else 1.0,
                                   "dof": 30, "p": 1e-9 if trends else 0.3, "needed_um_per_s": None, "excludes_drift": None}
        return [_test("creep", False, 1.0), drift, off]
    evals = [_cand("sensor_offset", True, 0.5), _cand("thermal_drift", False, 0.57, p=1.2e-3), _cand("creep", False, 1.0)]
    text = attribute(evals, tests_with(True))
    assert evals[0].name == "thermal_drift" and evals[0].significant, text
    assert "within the recordings moves" in evals[0].discrimination
    off = next(c for c in evals if c.name == "sensor_offset")
    assert not off.significant and off.veto and "attributed to thermal_drift" in off.veto
    # the same varying levels without a trend: the offset keeps the name
    evals = [_cand("sensor_offset", True, 0.5), _cand("thermal_drift", False, 0.57, p=1.2e-3), _cand("creep", False, 1.0)]
    attribute(evals, tests_with(False))
    assert evals[0].name == "sensor_offset" and evals[0].significant


def test_varying_levels_alone_neither_name_a_drift_nor_refuse_the_offset():
    """Varying levels are the drift's only when its own curve has the size; they do not refuse an offset (a reveal
    recording of another kind can sit further off than the calibration's histories say: development offset cases
    s110-002 and s110-017 named `none` when they did)."""
    evals = [_cand("sensor_offset", True, 0.5), _cand("thermal_drift", False, 0.95), _cand("creep", False, 1.0)]
    tests = [_test("creep", False, 1.0), _with_spread(_test("thermal_drift", False, 0.9), True),
             _with_spread(_test("sensor_offset", True, 0.5), True)]
    attribute(evals, tests)
    assert evals[0].name == "sensor_offset" and evals[0].significant
    assert not next(c for c in evals if c.name == "thermal_drift").significant


def test_a_holding_drift_takes_the_level_the_offset_candidate_took():
    # s107-001-like: the drift's signature holds within the recordings (it goes before the offset), its own
    # candidate beyond the session's constant is small (0.91/1.00), the offset's candidate passed: drift
    evals = [_cand("sensor_offset", True, 0.6), _cand("thermal_drift", False, 0.95), _cand("creep", False, 1.0)]
    tests = [_test("creep", False, 1.0), _test("thermal_drift", True, 0.56), _test("sensor_offset", True, 0.86)]
    text = attribute(evals, tests)
    assert evals[0].name == "thermal_drift" and evals[0].significant
    assert "the level it took" in evals[0].discrimination or "took it" in text
    # without a passed or sized offset there is no size to take: nothing slow is named
    evals = [_cand("sensor_offset", False, 0.95), _cand("thermal_drift", False, 0.95), _cand("creep", True, 0.9)]
    tests = [_test("creep", False, 1.0), _test("thermal_drift", True, 0.56), _test("sensor_offset", True, 0.86)]
    attribute(evals, tests)
    assert not any(c.significant for c in evals)


def test_signature_test_carries_the_spread_in_its_dict():
    t = _with_spread(SignatureTest("sensor_offset", 0.5, [0.5, 0.5], 0.5, 1e-6, 10, True), True)
    assert t.as_dict()["level_spread"]["varies"] is True


def test_a_holding_drift_does_not_take_a_level_within_the_base_misfit():
    """The offset's level refused as within the base's own level misfit (round 11) is no drift's either."""
    evals = [_cand("sensor_offset", True, 0.6), _cand("thermal_drift", False, 0.95), _cand("creep", False, 1.0)]
    off = _test("sensor_offset", True, 0.86)
    off.level = {"refused": True, "within_base_misfit": True, "offset_um": [0.01], "quantile": 3.0,
                 "base_level_rms_um": 0.02, "histories": 16, "depends_on_level": False, "p": 0.5,
                 "fold_ratios": [1.0, 1.0]}
    attribute(evals, [_test("creep", False, 1.0), _test("thermal_drift", True, 0.56), off])
    assert not any(c.significant for c in evals)


def test_the_drift_term_carries_the_level_it_reached_and_leaves_the_calibration_alone():
    """Round 12: the refined model's drift adds its level (its constant per sensor-zero column, mean over the
    recordings) on the recordings after the calibration, so that the model with the term minus the model
    without is its regressors times its coefficients, level included; the calibration stays undrifted."""
    from piezoctl.ident import refined
    from piezoctl.ident.terms import TERMS
    from test_base_plane import drift_session_setup
    ctx, base, t, u, y, recs = drift_session_setup()
    term = TERMS["thermal_drift"]
    coef = [0.15, 0.15, 0.3, 0.002]          # the level per recording (one value), warm-up, trend
    par = dict(base, terms={"thermal_drift": term.term(ctx, (15.0, 1.0), coef)})
    assert par["terms"]["thermal_drift"]["level_um"] == pytest.approx(0.15)
    for s, r in zip(ctx.signals, recs):
        d = refined.simulate(par, t, u, t_session=float(r.meta["session_time_s"])) - y
        assert np.max(np.abs(d - term.regressors(ctx, s, (15.0, 1.0)) @ coef)) < 1e-9
    assert np.all(refined.simulate(par, t, u, t_session=0.0) == y)
