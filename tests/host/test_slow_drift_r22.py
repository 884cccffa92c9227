"""Round 22: a warm-up that began after the calibration ended is offered referenced at the first recording
(``ThermalDrift.settings``' ``"first"`` settings)."""

import types

import numpy as np

from piezoctl.ident.terms import TERMS

DT = 0.01


def _ctx(starts, durs, t0=0.0):
    # recordings on the session clock; the calibration ended at t0; one sensor-zero column for all of them
    sigs = [types.SimpleNamespace(t=np.arange(int(d / DT)) * DT, t_session=float(a), index=i)
            for i, (a, d) in enumerate(zip(starts, durs))]
    return types.SimpleNamespace(signals=sigs, drift_t0=float(t0),
                                 drift_span=float(max(a + d for a, d in zip(starts, durs)) - t0),
                                 duration=float(sum(durs)), n_rec=len(sigs))


def _warm_up(ctx, a_um, t_on, tau):
    return [a_um * -np.expm1(-np.maximum(s.t + s.t_session - t_on, 0.0) / tau) for s in ctx.signals]


def _fit(ctx, st, y):
    """Least squares of ``y`` on the setting's drift basis and one common level; the residual's RMS [um] and the
    coefficients (level, amplitude, slope), the basis' sign applied."""
    drift = TERMS["thermal_drift"]
    ref = drift._reference(ctx, st)
    B = np.vstack([st[1] * drift.basis(s.t, st[0], drift._t_from(ref, s.t_session)) for s in ctx.signals])
    X = np.column_stack([np.ones(B.shape[0]), B])
    th = np.linalg.lstsq(X, np.concatenate(y), rcond=None)[0]
    return float(np.sqrt(np.mean((np.concatenate(y) - X @ th) ** 2))), th


# s128-001's shape: the calibration ended at 0, the reveal 28.6 s later (24 s, 10 s and 4 s recordings)
STARTS, DURS = (28.6, 60.0, 72.5), (24.0, 10.4, 3.7)


def test_late_warm_up_is_offered_from_the_first_recording():
    drift = TERMS["thermal_drift"]
    ctx = _ctx(STARTS, DURS)
    grid = drift.settings(ctx)
    old = [st for st in grid if len(st) == 2]
    assert {st[0] for st in old} == {np.inf}   # referenced at the calibration's end only the line is left
    first = [st for st in grid if len(st) == 3]
    assert {st[0] for st in first} == {5.0, 15.0} and {st[1] for st in first} == {1.0, -1.0}
    assert drift._reference(ctx, first[0]) == STARTS[0] and drift._reference(ctx, old[0]) == 0.0


def test_any_onset_before_the_first_recording_is_fitted_exactly():
    ctx = _ctx(STARTS, DURS)
    for t_on in (0.0, 10.0, 25.0, 28.6):   # the onset is unknown: the basis from the first recording fits each
        y = _warm_up(ctx, -0.68, t_on, 15.0)
        rms, th = _fit(ctx, (15.0, -1.0, "first"), y)
        assert rms < 1e-9 and th[1] >= 0.0 and abs(th[2]) < 1e-9
        line, _ = _fit(ctx, (np.inf, -1.0), y)   # the line the grid offered before leaves a warm-up's curvature
        assert line > 0.005   # 10 nm RMS with the onset at the calibration's end, 31 nm and more after it


def test_the_model_applies_the_reference_it_was_fitted_at():
    drift = TERMS["thermal_drift"]
    ctx = _ctx(STARTS, DURS)
    st = (15.0, -1.0, "first")
    y = _warm_up(ctx, -0.68, 20.0, 15.0)
    _, th = _fit(ctx, st, y)
    p = {"amplitude_um": -th[1], "tau_s": 15.0, "slope_um_per_s": -th[2], "level_um": th[0],
         "t0_session_s": drift._reference(ctx, st)}
    for s, yy in zip(ctx.signals, y):
        sim = types.SimpleNamespace(t=s.t, t_session=s.t_session, y=np.zeros(s.t.size))
        drift.apply(p, sim)
        assert np.max(np.abs(sim.y - yy)) < 1e-9
    cal = types.SimpleNamespace(t=np.arange(100) * DT, t_session=-5.0, y=np.zeros(100))
    drift.apply(p, cal)   # on the calibration the drift adds nothing, its level neither
    assert not np.any(cal.y)


def test_nothing_added_when_the_recordings_follow_the_calibration():
    drift = TERMS["thermal_drift"]
    ctx = _ctx((0.0, 30.0, 45.0), DURS)
    assert all(len(st) == 2 for st in drift.settings(ctx))
