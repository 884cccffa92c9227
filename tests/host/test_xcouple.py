"""Golden model of the cross-coupling predictor (host/piezoctl/golden/xcouple.py):
the float reference equals the host's hammerstein model on the controller's
scales, the fixed point stays within a worked bound of the float, and the
checks refuse what the firmware's init refuses."""

import dataclasses

import numpy as np
import pytest

from piezoctl.fixed import QOverflowError
from piezoctl.golden import xcouple as X
from piezoctl.ident import hammerstein as H
from piezoctl.tables.from_model import Scale


def _model(rng, degree=2, m=2, powers=(0, 1, 2, 3), channels=2):
    """A fitted hammerstein model on synthetic coupling data (drive 0..150 V, position 0..18 um)."""
    us, xs, ys = [], [], []
    for x in (1.0, 9.0, 17.0):
        t = np.arange(3000)
        u = 75 + 70 * np.sin(2 * np.pi * t / 1000.0) + 3 * np.sin(2 * np.pi * t / 37.0)
        e = (u - 75) / 70
        y = 0.04 * (1 + 0.02 * (x - 9)) * (e + 0.2 * e ** 2)
        y = np.convolve(y, [0.6, 0.3, 0.1])[: t.size]
        us.append(u)
        xs.append(np.full(t.size, x))
        ys.append(y)
    return H.fit_arrays(us, xs, ys, m=m, degree=degree, powers=list(powers), harmonics=0,
                        channels=channels, refine=10), us, xs, ys


def test_float_reference_is_the_hammerstein_model_on_q15_scales():
    rng = np.random.default_rng(1)
    p, us, xs, ys = _model(rng)
    drive = Scale(0.0, 150.0, -2.0, 22.0)
    pos = Scale(0.0, 150.0, -2.0, 22.0)
    drive_per_um = 0.7 / pos.p_half   # FS drive per um: output = y [um] * this
    k = X.from_hammerstein(p, drive, pos, drive_per_um)
    for u, x in zip(us, xs):
        u_fs = drive.drive_to_fs(u)
        x_fs = pos.position_to_fs(x)
        y_ref = H.predict(p, u, x)
        y_k = X.process_float(k, u_fs, x_fs)
        # equal but for the kernel's clamp of the normalized inputs to +-(1 - 2^-15)
        # (the training range's ends map to +-1): at most max power 3 x 2^-15 relative
        np.testing.assert_allclose(y_k, y_ref * drive_per_um, rtol=0, atol=3 * 2.0 ** -15 * np.max(np.abs(y_ref * drive_per_um)))
        if x[0] == 9.0:  # the middle position, and the drive inside its range: no clamp, equal
            inner = np.abs(drive.drive_to_fs(u) - k.u_center / 32768) * k.u_gain < 0.999
            inner[np.argmin(inner):] = False  # up to the first clamped sample (the filters remember)
            assert inner.sum() > 50
            np.testing.assert_allclose(y_k[inner], (y_ref * drive_per_um)[inner], rtol=1e-9)
    # the channel rescaling: sum |eta_c| = 1 - 2^-18 each
    assert np.allclose(np.abs(k.eta).sum(axis=(1, 2)), 1.0 - 2.0 ** -18)


def test_fixed_point_within_bound_of_float():
    rng = np.random.default_rng(2)
    p, us, xs, _ = _model(rng)
    drive = pos = Scale(0.0, 150.0, -2.0, 22.0)
    k = X.from_hammerstein(p, drive, pos, 0.7 / pos.p_half)
    kq = X.quantize(k)
    for u, x in zip(us[:2], xs[:2]):
        uq = np.floor(drive.drive_to_fs(u) * 32768 + 0.5).astype(np.int64)
        xq = np.floor(pos.position_to_fs(x) * 32768 + 0.5).astype(np.int64)
        y_q = X.process_q(kq, uq, xq)
        y_f = X.process_float(k, uq / 32768.0, xq / 32768.0) * 32768.0
        # rounding: half an LSB at the output plus the q24 coefficients' and
        # states' rounding through a gain of a few (worked in docs/cross-coupling.md)
        assert np.max(np.abs(y_q - y_f)) <= 2.0, np.max(np.abs(y_q - y_f))
        assert np.ptp(y_f) > 100  # a real signal, not zeros


def test_error_report_bounds():
    r = X.error_report(T=4000)
    assert r["max_lsb"] <= 1.0 and r["peak_lsb"] > 300 and r["snr_db"] > 50


def test_golden_cases_cover_the_edges():
    cases = X.golden_cases()
    assert {"std", "max", "sat", "clamp", "single", "steps"} <= set(cases)
    k, u, x, y = cases["max"]
    assert np.abs(np.asarray(k.eta, dtype=np.int64)).sum(axis=(1, 2)).tolist() == [1 << 24] * k.n_ch
    shifts = X._state_shifts(k)
    xi = np.abs(np.asarray(k.xi, dtype=np.int64)).sum(axis=2)
    assert all(int(xi[c, i]) + 1 == 1 << (35 - shifts[i]) for c in range(k.n_ch) for i in range(k.m))
    assert k.m == X.MAX_M and k.n_pow == X.MAX_POW and k.n_deg == X.MAX_DEG
    _, _, _, ys = cases["sat"]
    assert ys.max() == 32767 and ys.min() == -32768


def test_checks_refuse_like_init():
    k, *_ = X.golden_cases(T=60)["std"]
    X.check(k)
    a = np.asarray(k.a).copy()
    a[0, 1] = 1
    with pytest.raises(QOverflowError):
        X.check(dataclasses.replace(k, a=a))
    eta = np.asarray(k.eta).copy()
    eta[0, 0, 0] += (1 << 24)
    with pytest.raises(QOverflowError):
        X.check(dataclasses.replace(k, eta=eta))
    a = np.asarray(k.a).copy()
    a[0, 0] = (1 << 24) - 2000
    with pytest.raises(QOverflowError, match="state bound"):
        X.check(dataclasses.replace(k, a=a))
    with pytest.raises(ValueError, match="harmonics"):
        X.from_hammerstein({"harmonics": 5}, None, None, 1.0)
