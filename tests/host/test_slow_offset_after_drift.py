"""The offset tested after an accepted drift (slow_signature.offset_after_drift_test, round 13)."""

import types

import numpy as np

from piezoctl.diagnose.slow_signature import offset_after_drift_test
from piezoctl.ident.terms import TERMS

DT = 0.01


def _ctx(starts, dur):
    # three recordings on the session clock (the calibration ended at 0), one sensor-zero column each
    sigs = [types.SimpleNamespace(t=np.arange(int(dur / DT)) * DT, t_session=float(a), index=i)
            for i, a in enumerate(starts)]
    return types.SimpleNamespace(signals=sigs, valid=[np.ones(s.t.size, bool) for s in sigs], drift_t0=0.0,
                                 drift_span=float(starts[-1] + dur), duration=float(len(starts) * dur),
                                 n_rec=len(sigs), n_offset=lambda: len(sigs), offset_of=lambda i: i, base={})


def _model(ctx, y):
    """The drift as the diagnosis fits it (``ThermalDrift.columns``): the grid's best setting on the session
    clock beyond a free level per recording, the model keeping their mean (``level_um``); returns its
    parameters and the level each recording is left with (what a later offset candidate takes)."""
    drift = TERMS["thermal_drift"]
    n = ctx.signals[0].t.size
    R = np.kron(np.eye(len(ctx.signals)), np.ones((n, 1)))
    best = None
    for tau, sgn in drift.settings(ctx):
        if sgn < 0:
            continue
        B = np.vstack([drift.basis(s.t, tau, s.t_session) for s in ctx.signals])
        X = np.column_stack([R, B])
        th = np.linalg.lstsq(X, np.concatenate(y), rcond=None)[0]
        r = np.concatenate(y) - X @ th
        if best is None or r @ r < best[0]:
            best = (r @ r, tau, th)
    _, tau, th = best
    k = len(ctx.signals)
    lv = th[:k]
    p = {"tau_s": 1e300 if not np.isfinite(tau) else tau, "amplitude_um": 0.0 if not np.isfinite(tau) else th[k],
         "slope_um_per_s": th[k + 1], "level_um": float(np.mean(lv)), "t0_session_s": 0.0}
    return p, list(lv - np.mean(lv))


def _truth(ctx, offsets=(0.0, 0.0, 0.0)):
    # a 1 um warm-up with a 30 s time constant: the grid offers 5 s, 15 s and the slope alone over this span
    # (own sensor_offset case: offsets 0.3, -0.2, 0.15 um)
    return [1.0 * (1.0 - np.exp(-(s.t + s.t_session) / 30.0)) + o for s, o in zip(ctx.signals, offsets)]


def test_levels_the_drift_model_leaves_are_refused_as_an_offset():
    ctx = _ctx((5.0, 40.0, 80.0), 15.0)
    ctx.base["terms"] = {}
    p, left = _model(ctx, _truth(ctx))
    assert offset_after_drift_test(ctx, {"offset_um": left}) is None   # no drift accepted: nothing to test
    ctx.base["terms"] = {"thermal_drift": p}
    assert 0.01 < np.sqrt(np.mean(np.square(left)))   # the grid does leave levels (35 nm RMS here)
    r = offset_after_drift_test(ctx, {"offset_um": left})
    assert r["within_drift_misfit"] and r["drift_p"] >= 0.01
    assert r["drift_level_rms_um"] > 0


def test_a_true_offset_beside_the_drift_is_kept():
    ctx = _ctx((5.0, 40.0, 80.0), 15.0)
    p, left = _model(ctx, _truth(ctx, offsets=(0.3, -0.2, 0.15)))
    ctx.base["terms"] = {"thermal_drift": p}
    r = offset_after_drift_test(ctx, {"offset_um": left})
    assert not r["within_drift_misfit"] and r["drift_p"] < 0.01   # significance.ALPHA
