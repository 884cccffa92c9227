"""Round 23: a map of the reading (the sensor's curve) refused by the pooled exact check is read per recording in
the first round: it passes when, in each fold, the geometric mean of the recordings' held-out RMS ratios is below 1
and no recording is worse than ``WORSEN_MAX``. A history-dependent term, a later round and a map that does not help
the typical recording are refused as before."""

import types

import numpy as np
import pytest

from piezoctl.diagnose import select
from piezoctl.diagnose import significance as sg
from piezoctl.ident.terms import TERMS

NAMES = ["triangle", "steps", "slow_triangle"]


def _fold(per):
    return {"sse_before": sum(b for b, _ in per), "sse_after": sum(a for _, a in per), "n": 1000,
            "per_recording": per, "params": {}}


def _cand(name, folds):
    return select.Candidate(term=TERMS[name], ratio=0.6, fold_ratios=[0.6, 0.6], nrmse_before=3e-3,
                            nrmse_after=2e-3, t=5.0, p=1e-8, n_active=40, p_max=1e-3, dbic=-40.0, n_eff=500.0,
                            significant=True, setting=[None, None], coef=[None, None], credited=0.6,
                            exact=[_fold(p) for p in folds])


def _first(c, monkeypatch, later_round=False):
    # the branch-common re-sizing needs a real context; it is not what these tests are about
    monkeypatch.setattr(select, "_exact_on_common", lambda *a, **k: False)
    ctx = types.SimpleNamespace(names=NAMES)
    fctx = [ctx, types.SimpleNamespace(names=NAMES)] if later_round else [ctx, ctx]
    return select._first_exact([c], fctx, None, None, 1.0, lambda *_: None)


# s127-011's shape: the curve halves both triangles' error in each fold; the steps, whose base misfit is twenty
# times theirs, stay about as they were and decide the pooled ratio (fold 1 above 1)
TRIANGLES_HALVED = [[(0.25, 0.05), (5.0, 4.9), (0.25, 0.06)], [(0.25, 0.05), (5.0, 5.5), (0.25, 0.06)]]


def test_the_pooled_ratio_is_decided_by_the_recording_with_the_largest_base_misfit():
    fr = [np.sqrt(_fold(p)["sse_after"] / _fold(p)["sse_before"]) for p in TRIANGLES_HALVED]
    assert fr[1] >= 1.0
    gm = select.per_recording_ratios([_fold(p) for p in TRIANGLES_HALVED])
    assert max(gm) < 0.65
    assert gm[1] == pytest.approx((np.sqrt(0.05 / 0.25) * np.sqrt(5.5 / 5.0) * np.sqrt(0.06 / 0.25)) ** (1 / 3))


def test_a_curve_that_helps_each_typical_recording_passes_per_recording(monkeypatch):
    c = _cand("sensor_nonlinearity", TRIANGLES_HALVED)
    assert _first(c, monkeypatch) is c
    assert c.veto is None and c.worsened is None
    assert max(c.exact_fold_ratios) >= 1.0          # the pooled figures are kept and reported
    assert "weighted alike" in c.discrimination


def test_a_history_dependent_term_and_a_later_round_are_refused_as_before(monkeypatch):
    c = _cand("creep", TRIANGLES_HALVED)
    assert _first(c, monkeypatch) is None and "does not lower" in c.veto
    c = _cand("sensor_nonlinearity", TRIANGLES_HALVED)
    assert _first(c, monkeypatch, later_round=True) is None and "weighted alike" not in c.veto


def test_a_curve_that_does_not_help_the_typical_recording_is_refused(monkeypatch):
    # near s118-035's shape (a rate case, geometric mean 1.003 in fold 0): x1.06, x0.98, x0.97, mean 1.0025
    folds = [[(1.0, 1.06 ** 2), (1.0, 0.98 ** 2), (1.0, 0.97 ** 2)], [(1.0, 0.99 ** 2), (1.0, 0.89 ** 2),
                                                                      (1.0, 0.88 ** 2)]]
    c = _cand("sensor_nonlinearity", folds)
    assert _first(c, monkeypatch) is None
    assert "weighted alike" in c.veto and "does not lower" in c.veto


def test_a_curve_that_breaks_one_recording_is_refused_even_when_the_typical_one_improves(monkeypatch):
    # the triangles x0.2, the steps x1.6 in both folds (above WORSEN_MAX), pooled above 1
    folds = [[(1.0, 0.04), (5.0, 5.0 * 1.6 ** 2), (1.0, 0.04)]] * 2
    assert 1.6 > sg.WORSEN_MAX and max(select.per_recording_ratios([_fold(p) for p in folds])) < 1.0
    c = _cand("sensor_nonlinearity", folds)
    assert _first(c, monkeypatch) is None
    assert "steps x1.60" in c.veto
