"""Round 25: where the recordings leave the calibrated drive range, a sensor's curve must pass its size gate on the
samples inside it too (diagnose/select.inside_calibrated_veto)."""

import types

import numpy as np

from piezoctl.diagnose.select import inside_calibrated_veto
from piezoctl.ident.terms import TERMS

DT = 1e-3
CAL = (10.0, 120.0)   # [V] the calibrated drive range


def _ctx(u):
    """A fold context stub: one recording with drive ``u`` [V], every sample settled."""
    s = types.SimpleNamespace(u=u, dt=DT)
    return types.SimpleNamespace(signals=[s], valid=[np.ones(u.size, bool)], cal_u_lo=CAL[0], cal_u_hi=CAL[1],
                                 u_lo=float(u.min()), u_hi=float(u.max()))


def _triangle(hi, n=20000, period=2000):
    ph = (np.arange(n) % period) / period
    return CAL[0] + (hi - CAL[0]) * (1.0 - np.abs(2.0 * ph - 1.0))


def _within(x):
    return x <= 0.8


def _case(hi, inside_gain):
    """Residual: noise everywhere plus a part beyond the edge the correction takes in full; inside the range the
    correction takes ``inside_gain`` of a part of the same size."""
    rng = np.random.default_rng(0)
    u = _triangle(hi)
    beyond = u > CAL[1]
    x = np.where(beyond, (u - CAL[1]) / 10.0, np.sin(u / 7.0))
    e = x + 0.05 * rng.standard_normal(u.size)
    corr = np.where(beyond, x, inside_gain * x)
    fold = (np.arange(u.size) // 1000) % 2
    return _ctx(u), e, corr, fold


def test_a_curve_that_acts_only_beyond_the_edge_is_refused():
    ctx, e, corr, fold = _case(150.0, 0.0)
    why = inside_calibrated_veto(ctx, e, corr, fold, _within)
    assert why is not None and "beyond the calibrated drive range" in why and "fold ratios 1.00/1.00" in why


def test_a_curve_that_acts_inside_the_range_too_passes():
    ctx, e, corr, fold = _case(150.0, 1.0)
    assert inside_calibrated_veto(ctx, e, corr, fold, _within) is None


def test_recordings_inside_the_range_are_not_read():
    # 1 V beyond the edge is less than the knee grid's step (2.5 % of the span): the rule does not apply, even to a
    # correction that takes nothing inside
    ctx, e, corr, fold = _case(121.0, 0.0)
    assert inside_calibrated_veto(ctx, e, corr, fold, _within) is None


def test_only_the_sensor_curve_is_sized_inside():
    assert [n for n, t in TERMS.items() if t.sized_inside_calibration] == ["sensor_nonlinearity"]


def test_the_clip_gain_is_not_negative():
    # round 25: a rail takes displacement away; its linearized gain is bounded at zero (the other terms' bounds as
    # they were: the asymmetry's polynomial and the curve free)
    ctx = types.SimpleNamespace()
    assert TERMS["saturation"].lower(ctx) == [0.0]
    assert TERMS["asymmetric_hysteresis"].lower(ctx) is None
    assert TERMS["sensor_nonlinearity"].lower(ctx) is None
