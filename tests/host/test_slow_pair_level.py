"""Round 18: a sensor offset's signature on the recordings that sweep between the same extremes: their common level
on the loop against the base's own level misfit (slow_signature.same_shape_pairs' level, pair_level_test, and the
attribution's use of it)."""

import types

import numpy as np
import pytest

from piezoctl.diagnose import significance as sg
from piezoctl.diagnose import slow_signature as ss
from piezoctl.diagnose.slow_signature import ALPHA_SIGNATURE, SignatureTest, attribute

from test_slow_same_shape import _ctx, _stack, _triangle, _walk


def _misfit(s_l, h=16):
    return {"histories": [f"h{i}" for i in range(h)], "mse_um2": {"level": s_l ** 2, "slow": 0.0, "fast": 0.0}}


def test_the_pairs_common_level_is_the_offset_and_not_the_walks():
    """Two triangles and a walk 0.3 um off them (its own history's misfit): the pair's common level is the
    offset's, the loop's misfit (odd in the drive and in the direction) cancels over the bins."""
    drives = [_triangle(20.0, 0.3), _walk(15.0, np.random.default_rng(2)), _triangle(7.0, 0.8)]
    ctx = _ctx(drives, [30.0, 55.0, 75.0])
    for c in (0.4, -0.25, 0.0):
        r, rec, tt = _stack(ctx, lambda ts: c + 0 * ts)
        p = ss.same_shape_pairs(ctx, [r], rec, tt)[0]
        assert p["column"] == 0
        assert abs(p["level_um"] - c) < 3 * p["level_se_um"] + 5e-3, (c, p)
        # one recording's residual moved by 0.3 um (its history) moves the common level by half that, not all
        moved = r + np.where(rec == 2, 0.3, 0.0)
        q = ss.same_shape_pairs(ctx, [moved], rec, tt)[0]
        assert q["level_um"] - p["level_um"] == pytest.approx(0.15, abs=1e-9)


def _pair(c, se=0.01, d=0.0):
    return {"level_um": c, "level_se_um": se, "level_difference_um": d}


def test_a_pair_level_beyond_the_base_misfit_holds_and_one_within_it_does_not():
    mis = _misfit(0.05)
    q = ss.pair_level_test([_pair(0.4)], mis)["quantile"]
    assert 2.5 < q < 3.5   # t quantile at ALPHA / 1, 15 dof
    assert ss.pair_level_test([_pair(0.4)], mis)["holds"]
    assert ss.pair_level_test([_pair(-0.4)], mis)["holds"]
    assert not ss.pair_level_test([_pair(0.1)], mis)["holds"]          # within q s_L
    assert not ss.pair_level_test([_pair(0.4, se=0.2)], mis)["holds"]  # the pair's own error too large
    assert not ss.pair_level_test([_pair(0.4), _pair(-0.4)], mis)["holds"]   # no one level
    # s117-027-like (a Bouc-Wen null): the two loops 0.2 um apart carry their own history, the level is not one
    # sensor zero's; the same level with the loops agreeing holds
    assert not ss.pair_level_test([_pair(0.45, d=0.2)], _misfit(0.11))["holds"]
    assert ss.pair_level_test([_pair(0.45, d=0.02)], _misfit(0.11))["holds"]
    assert ss.pair_level_test([], mis) is None
    assert ss.pair_level_test([_pair(0.4)], {"histories": [], "mse_um2": {"level": 0.0}}) is None


def _cand(name, significant, ratio, p=1e-6):
    return types.SimpleNamespace(name=name, significant=significant, veto=None, fold_ratios=[ratio, ratio],
                                 credited=ratio, dbic=-10.0, p=p, discrimination=None, slow_signature=None)


def _tests(pair_c, refused=False, trends=False, excludes=True):
    """The three signatures as on development s119-033: none holds by its unique contribution (the walk's level
    is not the triangles'); the trend's pair sits at ``pair_c``."""
    trend = {"slope_um_per_s": 0.0, "se_um_per_s": 1e-3, "t": 0.0, "dof": 40, "p": 0.9 if not trends else 1e-6,
             "trends": trends, "levels_um": [-0.46], "needed_um_per_s": [-0.016], "excludes_drift": excludes,
             "against_level": False, "same_shape": [], "pair_level": ss.pair_level_test([_pair(pair_c)], _misfit(0.086))}
    out = []
    for n, r in (("creep", 1.26), ("thermal_drift", 1.26), ("sensor_offset", 0.93)):
        t = SignatureTest(name=n, unique_ratio=r, fold_ratios=[r, r], credited=r, p=0.5, n_active=20, holds=False)
        if n in ("thermal_drift", "sensor_offset"):
            t.trend = trend
        if n == "sensor_offset":
            t.level = {"refused": refused, "within_base_misfit": refused, "offset_um": [-0.14],
                       "base_level_rms_um": 0.086, "quantile": 2.95, "histories": 16, "p": 1.0,
                       "fold_ratios": [1.0, 1.0], "depends_on_level": False}
        out.append(t)
    return out


@pytest.mark.parametrize("refused", [False, True])
def test_the_offset_is_named_on_its_pair_level_and_not_without_it(refused):
    """The pair beyond the base's misfit names the offset, also where the joint fit's one constant per session
    (dragged by the walk) lies within it; a pair within the misfit leaves the verdict ``none``."""
    evals = [_cand("sensor_offset", True, 0.2)]
    text = attribute(evals, _tests(-0.70, refused=refused))
    assert evals[0].significant and not evals[0].veto, text
    assert "sweep between the same extremes" in text
    evals = [_cand("sensor_offset", True, 0.2)]
    text = attribute(evals, _tests(-0.10, refused=refused))
    assert not evals[0].significant and evals[0].veto, text


def test_a_trending_level_still_goes_to_the_drift_and_a_drift_not_excluded_is_the_pair():
    evals = [_cand("sensor_offset", True, 0.2), _cand("thermal_drift", False, 0.5)]
    attribute(evals, _tests(-0.70, trends=True))
    assert evals[0].name == "thermal_drift" and evals[0].significant
    evals = [_cand("sensor_offset", True, 0.2)]
    attribute(evals, _tests(-0.70, excludes=False))
    assert evals[0].significant and evals[0].slow_alternative["name"] == "thermal_drift"


def test_a_refusal_by_the_drifts_model_is_not_lifted_by_the_pair():
    tests = _tests(-0.70, refused=True)
    tests[2].level.update(within_drift_misfit=True, drift_level_rms_um=0.5, drift_f=0.5, drift_p=0.8)
    evals = [_cand("sensor_offset", True, 0.2)]
    attribute(evals, tests)
    assert not evals[0].significant


def _drift_cand(credited_only=True):
    return types.SimpleNamespace(name="thermal_drift", significant=False, veto="credited 0.86" if credited_only
                                 else "not significant", credited=0.86, credited_only=credited_only, p=1.8e-5,
                                 p_max=1e-3, fold_ratios=[0.59, 0.68], discrimination=None)


def _run_on_pairs(monkeypatch, cand, diffs):
    pairs = [{"recordings": [0, 2], "level_difference_um": d, "se_um": 0.007, "dt_s": 38.0, "bins": 31}
             for d in diffs]
    monkeypatch.setattr(ss, "signature_groups", lambda ctx: {})
    monkeypatch.setattr(ss, "level_trend_test", lambda *a, **k: {"same_shape": pairs})
    ctx = types.SimpleNamespace(valid=[np.ones(10, bool)] * 3)
    ss.drift_on_pair([cand], [ctx, ctx], [None, None], [(None, None, None)] * 2, None, None, 1000, lambda *a: None)
    return cand


def test_a_drift_refused_by_the_credited_ratio_passes_on_a_pair_that_moved(monkeypatch):
    """s119-001-like: the two triangles differ by 0.25 +- 0.007 um; the base's misfit cancels on the pair."""
    c = _run_on_pairs(monkeypatch, _drift_cand(), [0.246])
    assert c.significant and c.veto is None and "differ by +0.2460" in c.discrimination


@pytest.mark.parametrize("cand,diffs", [(True, [0.01]),           # within the pair's error (t 1.4)
                                        (True, [0.2, -0.2]),      # two pairs, opposite ways
                                        (False, [0.246])])        # refused for another reason than the credit
def test_a_drift_does_not_pass_on_a_pair_that_did_not_move_one_way_or_when_refused_otherwise(monkeypatch, cand, diffs):
    c = _run_on_pairs(monkeypatch, _drift_cand(cand), diffs)
    assert not c.significant and c.veto is not None
