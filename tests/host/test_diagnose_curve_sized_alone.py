"""Round 28: a map of the reading (the sensor's curve) refused by the exact check in the first round is checked
again with its model sized on its own columns alone (no nested nuisance), as the refined model holds it. The
coefficients must be the plain least squares of the residual on the curve's columns per training fold; it passes
only when each fold's exact held-out error is lower and no recording is worse than ``WORSEN_MAX``; a
history-dependent term and a later round never reach it."""

import types

import numpy as np
import pytest

from piezoctl.diagnose import select
from piezoctl.diagnose import significance as sg
from piezoctl.ident.terms import TERMS

NAMES = ["triangle", "steps", "slow_triangle"]
N = 600


def _ctx(seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, N)
    X = np.column_stack([q ** 2, q ** 3, np.ones(N)])
    e = X @ [0.2, -0.1, 0.05] + 0.01 * rng.standard_normal(N)
    ctx = types.SimpleNamespace(names=NAMES, design_cache={}, X=X, e=e)
    return ctx


def _patch(monkeypatch, ctx, sse_after):
    """residual and design from ``ctx``; the exact fold's sums from ``sse_after(f, coef)`` (per recording)."""
    seen = {}
    monkeypatch.setattr(select, "residual", lambda c: c.e)
    monkeypatch.setattr(select, "_design", lambda c, term, st: c.design_cache.setdefault(
        (term.name, repr(st)), types.SimpleNamespace(X=c.X)))

    def exact(c, cand, f, fold_all, recs):
        seen[f] = np.asarray(cand.coef[f], float)
        per = [(1.0, a) for a in sse_after(f, cand.coef[f])]
        return {"sse_before": 3.0, "sse_after": sum(a for _, a in per), "n": 100, "per_recording": per,
                "params": {}}
    monkeypatch.setattr(select, "_exact_fold", exact)
    return seen


def _cand(name="sensor_nonlinearity"):
    return select.Candidate(term=TERMS[name], ratio=0.6, fold_ratios=[0.66, 0.61], nrmse_before=3e-3,
                            nrmse_after=2e-3, t=5.0, p=1e-9, n_active=60, p_max=1e-3, dbic=-200.0, n_eff=500.0,
                            significant=True, setting=[None, None], coef=[np.array([2.0, 1.0, 0.0])] * 2,
                            credited=0.68, exact_fold_ratios=[1.40, 1.20],
                            veto="the exact simulation of the refined model with this term does not lower")


FOLDS = np.arange(N) % 2


def test_the_curve_is_sized_on_its_own_columns_per_training_fold_and_passes(monkeypatch):
    ctx = _ctx()
    seen = _patch(monkeypatch, ctx, lambda f, coef: [0.3, 0.5, 0.3])
    c = _cand()
    assert select._exact_sized_alone(c, [ctx, ctx], FOLDS, None, 1.0, lambda *_: None)
    for f in (0, 1):
        tr = FOLDS == f
        want = np.linalg.lstsq(ctx.X[tr], ctx.e[tr], rcond=None)[0]
        assert seen[f] == pytest.approx(want, rel=1e-6, abs=1e-9)
        assert c.coef[f] == pytest.approx(want, rel=1e-6, abs=1e-9)
    assert seen[0] == pytest.approx([0.2, -0.1, 0.05], abs=0.01)   # the curve itself, not the nested split
    assert c.veto is None and c.worsened is None and c.sized_alone   # the all-data model is sized alone too
    assert c.exact_fold_ratios == pytest.approx([np.sqrt(1.1 / 3.0)] * 2)
    assert "sized on its own columns alone" in c.discrimination
    assert ("sensor_nonlinearity", "None") not in ctx.design_cache   # not kept beyond the check


def test_a_fold_not_lowered_or_a_recording_made_worse_is_refused(monkeypatch):
    ctx = _ctx()
    _patch(monkeypatch, ctx, lambda f, coef: [0.3, 0.5, 0.3] if f == 0 else [1.2, 1.2, 1.2])
    c = _cand()
    assert not select._exact_sized_alone(c, [ctx, ctx], FOLDS, None, 1.0, lambda *_: None)
    assert "nor sized on its own columns alone" in c.veto and c.exact_fold_ratios == [1.40, 1.20]
    assert not c.sized_alone
    # pooled lower in each fold, but the steps worse than WORSEN_MAX over both folds
    k = 1.6
    assert k > sg.WORSEN_MAX
    _patch(monkeypatch, ctx, lambda f, coef: [0.05, k ** 2, 0.05])
    c = _cand()
    assert not select._exact_sized_alone(c, [ctx, ctx], FOLDS, None, 1.0, lambda *_: None)
    assert "steps x1.60" in c.veto


def test_reached_from_the_exact_check_for_a_map_in_the_first_round_only(monkeypatch):
    calls = []
    monkeypatch.setattr(select, "_exact_on_common", lambda *a, **k: False)
    monkeypatch.setattr(select, "_exact_per_recording", lambda *a, **k: False)
    monkeypatch.setattr(select, "_exact_sized_alone", lambda c, *a, **k: calls.append(c.name) or True)
    bad = {"sse_before": 1.0, "sse_after": 1.5, "n": 10, "per_recording": [(1.0, 1.5)] * 3, "params": {}}
    ctx = types.SimpleNamespace(names=NAMES)
    for name, fctx in (("creep", [ctx, ctx]), ("sensor_nonlinearity", [ctx, types.SimpleNamespace(names=NAMES)])):
        c = _cand(name)
        c.veto, c.exact = None, [bad, bad]
        assert select._first_exact([c], fctx, None, None, 1.0, lambda *_: None) is None
    assert calls == []
    c = _cand()
    c.veto, c.exact = None, [bad, bad]
    assert select._first_exact([c], [ctx, ctx], None, None, 1.0, lambda *_: None) is c
    assert calls == ["sensor_nonlinearity"]
