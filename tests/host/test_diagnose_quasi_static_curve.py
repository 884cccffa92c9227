"""Round 24: after a drive-side term, a map of the reading (the sensor's curve) is read on the samples where the
drive is quasi-static, where a drive-side term's leftover (which grows with the drive's rate) does not act."""

import types

import numpy as np

from piezoctl.diagnose import select
from piezoctl.ident.terms import TERMS

DT = 1e-4


def _sig(u):
    return types.SimpleNamespace(u=np.asarray(u, float), dt=DT)


def _ctx(us, terms=None):
    return types.SimpleNamespace(base={"u_mid": 50.0, "u_half": 50.0, "terms": terms or {}},
                                 signals=[_sig(u) for u in us], valid=[np.ones(len(u), bool) for u in us], dt=DT,
                                 misfit={"mse_um2": {"level": 1e-4, "slow": 1e-4, "fast": 1e-4}})


def _triangle(f, n, lo=0.0, hi=100.0):
    t = np.arange(n) * DT
    ph = (t * f) % 1.0
    return lo + (hi - lo) * np.where(ph < 0.5, 2 * ph, 2 - 2 * ph)


def test_drive_side_accepted_reads_the_model_terms():
    assert select.drive_side_accepted(_ctx([np.zeros(10)], {"delay": {}}))
    assert select.drive_side_accepted(_ctx([np.zeros(10)], {"creep": {}, "amplifier_slew_limit": {}}))
    assert not select.drive_side_accepted(_ctx([np.zeros(10)], {"creep": {}, "sensor_offset": {}}))
    assert not select.drive_side_accepted(_ctx([np.zeros(10)]))


def test_the_quasi_static_samples_are_the_slow_drive_not_the_fast_sines():
    n = 20000
    slow = _triangle(0.5, n)                                            # 0.5 Hz over the stroke
    fast = 50.0 + 10.0 * np.sin(2 * np.pi * 200.0 * np.arange(n) * DT)   # 200 Hz
    steps = np.repeat([20.0, 80.0, 30.0, 70.0], n // 4)
    m = select.quasi_static_mask(_ctx([slow, fast, steps]))
    q = [m[:n], m[n:2 * n], m[2 * n:]]
    assert q[0][1000:-1000].mean() > 0.9
    assert q[1][1000:-1000].mean() < 0.05
    jumps = np.flatnonzero(np.diff(steps)) + 1
    assert q[2][[2500, 7500, 12500, 17500]].all() and not q[2][jumps].any()   # the dwells, not the steps' edges
    assert q[2][1000:-1000].mean() > 0.75


def _ctxs(with_curve, rng):
    """Two folds' contexts of one model and its residual on two recordings, a slow triangle (quasi-static) and
    fast sines: a level per recording (0.3 and -0.2 um), on the fast one a drive-side leftover ~ the rate (1 um),
    noise, and with ``with_curve`` a static map of y (0.2 um q^2) on both."""
    n = 40000
    slow = _triangle(0.5, n)
    fast = 50.0 + 40.0 * np.sin(2 * np.pi * 60.0 * np.arange(n) * DT)
    us = [slow, fast]
    ctx = _ctx(us, {"delay": {}})
    for s, u in zip(ctx.signals, us):
        s.yb = 0.3 * u
    ctx.n_rec, ctx.y_center, ctx.y_half, ctx.design_cache = 2, 15.0, 15.0, {}
    ctx2 = types.SimpleNamespace(**{**vars(ctx), "design_cache": {}})
    q = (0.3 * np.concatenate(us) - 15.0) / 15.0
    rate = np.gradient(fast, DT)
    e = (np.r_[np.full(n, 0.3), np.full(n, -0.2)] + np.r_[np.zeros(n), rate / np.abs(rate).max()]
         + 0.005 * rng.standard_normal(2 * n) + (0.2 * q ** 2 if with_curve else 0.0))
    blocks = np.arange(2 * n) // 4000
    return [ctx, ctx2], [e, e], blocks % 2, blocks


def _reading(with_curve, seed, monkeypatch):
    monkeypatch.setattr(select, "_nuis", lambda *a, **k: None)   # no base to refit in this synthetic model
    ctxs, es, fold, blocks = _ctxs(with_curve, np.random.default_rng(seed))
    e = es[0]
    pooled = np.linalg.lstsq(select._design(ctxs[0], TERMS["sensor_nonlinearity"], None).X, e, rcond=None)[1]
    r = select._quasi_static_reading(ctxs, TERMS["sensor_nonlinearity"], es, fold, blocks, 100000, 3, 1e-3,
                                     lambda x: x <= 0.8)
    return float(np.sqrt(pooled[0] / np.sum(e ** 2))), r


def test_a_curve_beside_a_fast_leftover_and_levels_passes_on_the_quasi_static_part(monkeypatch):
    pooled, r = _reading(True, 0, monkeypatch)
    assert pooled > 0.8                             # fitted on every sample, the leftover and the levels decide
    assert r["passes"] and max(r["fold_ratios"]) < 0.2
    assert 0.3 < r["fraction"] < 0.7


def test_without_a_curve_the_levels_and_the_leftover_are_not_credited_to_it(monkeypatch):
    _, r = _reading(False, 1, monkeypatch)
    assert not r["passes"] and min(r["fold_ratios"]) > 0.95


def test_the_model_is_sized_on_the_quasi_static_samples_beside_the_levels(monkeypatch):
    monkeypatch.setattr(select, "_nuis", lambda *a, **k: None)
    ctxs, es, fold, _ = _ctxs(True, np.random.default_rng(3))
    q_fast = (ctxs[0].signals[1].yb - 15.0) / 15.0
    e = es[0] + np.r_[np.zeros(q_fast.size), 0.5 * q_fast ** 3]   # a leftover of the fast recording a cube takes
    st, th = select.fit_on_quasi_static(ctxs[0], TERMS["sensor_nonlinearity"], e, fold >= 0, 100000)
    assert st is None and len(th) == 3
    assert abs(th[0] - 0.2) < 0.02 and abs(th[1]) < 0.02   # the map's q^2, not the fast one's cube
