"""Round 25: the sensor curve's branch-common reading (round 19) and its branch-common sizing in the exact check
(round 20), first-round only before, are also offered in a round after a drive-side term (a delay, a pole, a slew
limit), each fold's figures from that fold's model. The physics: a drive-side term's leftover is a lag, ~ d du/dt,
of opposite sign on the rising and falling branches at equal y, and averages out of what the branches share; a map
of the reading passes unchanged."""

import types

import numpy as np

from piezoctl.diagnose import select, static_map
from piezoctl.ident.terms import TERMS


def _triangles(n_cycles=8, n=400, amp=10.0):
    """y [um] of a triangle sweep (rising and falling ramps), its branch ids and alternate folds by cycle."""
    ramp = np.linspace(-amp, amp, n)
    y = np.concatenate([np.concatenate([ramp, ramp[::-1]]) for _ in range(n_cycles)])
    branch = np.repeat(np.arange(2 * n_cycles), n)
    fold = np.repeat(np.arange(n_cycles) % 2, 2 * n)
    return y, branch, fold


def _curve_columns(y):
    q = y / np.max(np.abs(y))
    return np.column_stack([q ** 2, q ** 3, np.ones_like(q)])


def test_lag_leftover_averages_out_while_the_curve_passes():
    y, branch, fold = _triangles()
    rng = np.random.default_rng(0)
    lag = 0.3 * np.sign(np.gradient(y))            # a delay's leftover on a triangle: +-d dy/dt, by direction
    curve = 0.2 * (y / 10.0) ** 2 - 0.1 * (y / 10.0) ** 3
    noise = 0.01 * rng.standard_normal(y.size)
    X = _curve_columns(y)
    with_curve = static_map.branch_common_test(y, branch, lag + curve + noise, X, None, fold)
    lag_only = static_map.branch_common_test(y, branch, lag + noise, X, None, fold)
    assert max(with_curve["fold_ratios"]) < 0.3 and with_curve["p"] < 0.01   # the family level
    assert min(lag_only["fold_ratios"]) > 0.9      # nothing of the lag is left for the curve to take


def _bc(fr, p, cr, per, coef):
    return {"fold_ratios": fr, "p": p, "credited_ratio": cr, "per_recording": per, "coef": coef,
            "n_bins": 40, "before_um": 0.2, "after_um": 0.1}


def test_first_round_is_the_one_model(monkeypatch):
    calls = []
    monkeypatch.setattr(select, "_branch_common", lambda ctx, term, e, fold, st: calls.append((ctx, e, st)) or "bc")
    ctx = object()
    out = select._branch_common_folds([ctx, ctx], TERMS["sensor_nonlinearity"], ["e0", "e0"], None, [None, None])
    assert out == "bc" and calls == [(ctx, "e0", None)]


def test_after_a_term_each_fold_from_its_own_model_conservatively(monkeypatch):
    c0, c1 = object(), object()
    figs = {id(c0): _bc([0.5, 0.9], 1e-5, 0.6, {"a": 0.7, "b": 0.9}, [[1.0, 2.0], [9.0, 9.0]]),
            id(c1): _bc([0.9, 0.6], 1e-3, 0.7, {"a": 0.95, "b": 0.8}, [[8.0, 8.0], [3.0, 4.0]])}
    monkeypatch.setattr(select, "_branch_common", lambda ctx, term, e, fold, st: figs[id(ctx)])
    out = select._branch_common_folds([c0, c1], TERMS["sensor_nonlinearity"], ["e0", "e1"], None, [None, None])
    assert out["fold_ratios"] == [0.5, 0.6]           # fitted on fold f with fold f's model
    assert out["coef"] == [[1.0, 2.0], [3.0, 4.0]]
    assert out["p"] == 1e-3 and out["credited_ratio"] == 0.7
    assert out["per_recording"] == {"a": 0.95, "b": 0.9}
    figs[id(c1)] = None
    assert select._branch_common_folds([c0, c1], TERMS["sensor_nonlinearity"], ["e0", "e1"], None,
                                       [None, None]) is None


def _refused_curve(whole):
    c = select.Candidate(term=TERMS["sensor_nonlinearity"], ratio=0.9, fold_ratios=[0.9, 0.9], nrmse_before=3e-3,
                         nrmse_after=2.7e-3, t=5.0, p=1e-8, n_active=40, p_max=1e-3, dbic=-40.0, n_eff=500.0,
                         significant=True, setting=[None, None], coef=[None, None], credited=0.6, whole=whole,
                         exact=[{"sse_before": 1.0, "sse_after": 1.2, "n": 10, "per_recording": [(1.0, 1.2)],
                                 "params": {}}] * 2)
    return c


def test_later_round_sizes_on_the_common_part_only_after_that_reading(monkeypatch):
    calls = []
    monkeypatch.setattr(select, "_exact_on_common", lambda c, *a, **k: calls.append(c.name) or False)
    fctx = [types.SimpleNamespace(names=["r"]), types.SimpleNamespace(names=["r"])]   # a later round: two models
    select._first_exact([_refused_curve(None)], fctx, None, None, 1.0, lambda *_: None)
    assert calls == []                                 # passed the pooled gates: main's path, no re-sizing
    select._first_exact([_refused_curve({"branch_common": {}})], fctx, None, None, 1.0, lambda *_: None)
    assert calls == ["sensor_nonlinearity"]
