"""Round 24: the reveal's shift from the calibration's own orbit (slow_signature.calibration_orbit_test).

A drive that repeats one cycle between the same extremes settles on one orbit, whatever its rate; a moved sensor
zero shifts every bin of it alike, a lag moves the two directions apart (cancels in their mean), a drift moves the
cycle means. Sizes as round 23's held-out s132-033 (Bouc-Wen, offset -0.142 um; the orbits' shift -0.143 um on the
foreign stage's measured output) and s132-002 (+0.376 um; +0.376 um)."""

import types

import numpy as np

from piezoctl.diagnose import slow_signature as ss

FS = 10000.0   # [Hz], the foreign stage's rate (a bin's samples on the steep branch resolve its mean)


def _triangle(n_cycles, period, lo=0.0, hi=100.0):
    t = np.arange(int(n_cycles * period * FS)) / FS
    ph = (t / period) % 1.0
    return t, lo + (hi - lo) * (1.0 - 2.0 * np.abs(ph - 0.5))   # a maximum at every period's start


def _loop(u, lag_s=0.0, rate=0.0):
    """A hysteretic orbit between 0 and 100 V [um]: a branch per direction (a Duhem-like loop's limit), plus a
    lag's share odd in the direction (``rate`` [V/s] x ``lag_s``)."""
    d = np.sign(np.gradient(u))
    x = u / 100.0
    return 20.0 * x + 0.8 * np.sin(np.pi * x) * d - 0.01 * rate * lag_s * d


def _ctx(cal, rev, col=0):
    """cal, rev: lists of (u, y); the reveal in sensor-zero column ``col`` (-1: the calibration's session)."""
    sig = [types.SimpleNamespace(u=u, y=y, t=np.arange(u.size) / FS, index=i) for i, (u, y) in enumerate(rev)]
    return types.SimpleNamespace(cal=[types.SimpleNamespace(u=u, y=y) for u, y in cal], signals=sig,
                                 valid=[s.t >= 0.5 for s in sig], offset_of=lambda i: col)


def _case(offset=0.0, drift=0.0, noise=0.006, seed=0, rev_hi=100.0, converge=0.0):
    rng = np.random.default_rng(seed)
    tc, uc = _triangle(9, 1.5)                    # the calibration's triangle, 0.67 Hz
    tr, ur = _triangle(10, 0.8, 0.0, rev_hi)       # the reveal's, 1.25 Hz: another rate, the same extremes
    yc = _loop(uc, 0.002, 133.0) + noise * rng.standard_normal(uc.size)
    # converge: a Duhem loop's entry onto its orbit, decaying with a 0.6 s time constant from the recording's start
    yr = _loop(ur, 0.002, 250.0) + offset + drift * tr / tr[-1] - converge * np.exp(-tr / 0.6) \
        + noise * rng.standard_normal(ur.size)
    return _ctx([(uc, yc)], [(ur, yr)])


def test_an_offset_is_the_orbits_shift_beyond_a_lag_and_the_noise():
    for off in (-0.142, 0.376):
        ob = ss.calibration_orbit_test(_case(offset=off))
        assert ob is not None and ob["holds"]
        assert abs(ob["shift_um"][0] - off) < 0.005   # the lag (odd in the direction) cancels
    ob = ss.calibration_orbit_test(_case(offset=-0.142, converge=0.7))   # the loop's entry is left out
    assert ob["holds"] and abs(ob["shift_um"][0] + 0.142) < 0.005


def test_no_offset_does_not_hold():
    held = [ss.calibration_orbit_test(_case(seed=s))["holds"] for s in range(20)]
    assert sum(held) <= 1


def test_a_drift_moves_the_cycle_means_and_is_refused():
    ob = ss.calibration_orbit_test(_case(offset=0.1, drift=0.2))
    assert ob is not None and not ob["holds"] and ob["pairs"][0]["moving_um"] > 0.1


def test_other_extremes_or_the_calibrations_session_give_no_test():
    assert ss.calibration_orbit_test(_case(offset=0.2, rev_hi=80.0)) is None
    ctx = _case(offset=0.2)
    ctx.offset_of = lambda i: -1
    assert ss.calibration_orbit_test(ctx) is None


def test_the_orbit_is_reported_and_decides_nothing():
    """Reported with the offset's signature; the offset's refusal by the base's level misfit is as before."""
    ob = ss.calibration_orbit_test(_case(offset=-0.142))
    t = ss.SignatureTest(name="sensor_offset", unique_ratio=0.9, fold_ratios=[0.9, 0.9], credited=0.9, p=0.5,
                         n_active=10, holds=False, orbit=ob,
                         level={"offset_um": [-0.2], "refused": True, "within_base_misfit": True,
                                "within_drift_misfit": False})
    assert t.as_dict()["calibration_orbit"]["holds"]
    assert f"{ob['shift_um'][0]:+.3f} +- " in t.phrase() and "off it, beyond" in t.phrase()
    assert ss._level_refused(t) and ss._precedence([t], set()) == []
