"""Prandtl-Ishlinskii family: float reference, inverse, small gain, golden models."""

from __future__ import annotations


import numpy as np
import pytest

from piezoctl import fixed
from piezoctl.fixed import QOverflowError
from piezoctl.golden import eupi as geupi
from piezoctl.golden import eupi_inv as ginv
from piezoctl.golden import play as gplay
from piezoctl.golden.error_table import error_stats
from piezoctl.models.eupi import (EUPIParams, apply_kex, choose_kex, cpi_inverse_params,
                                  eupi_inverse, eupi_model, poly_eval, slope_bounds,
                                  small_gain_margin)
from piezoctl.models.play import play_outputs

# Documented in docs/kernels-pi.md ("Measured float-versus-fixed error").
MAX_ERR_LSB = {"play": 1.0, "eupi": 1.0, "eupi_inv": 2.5}


def _naive_play(u, r, a, y0):
    """One operator, scalar loop, straight from the equation."""
    f = y0
    out = []
    for x in u:
        f = max(x - r, min(a * (x + r), f))
        out.append(f)
    return np.array(out)


def _smooth_yr(n=20000, fs=10e3):
    t = np.arange(n) / fs
    return 0.45 * np.sin(2 * np.pi * 10 * t) * (0.6 + 0.4 * np.cos(2 * np.pi * 1.1 * t)) \
        + 0.05 * np.sin(2 * np.pi * 61 * t)


# ------------------------------------------------------------------ play_outputs


def test_play_outputs_matches_scalar_loop():
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(0, 0.05, 3000))
    r = rng.uniform(0, 0.8, 12)
    a = rng.uniform(0.3, 2.0, 12)
    y0 = rng.uniform(-0.5, 0.5, 12)
    got = play_outputs(u, r, a, y0)
    assert got.shape == (3000, 12)
    for i in range(12):
        np.testing.assert_array_equal(got[:, i], _naive_play(u, r[i], a[i], y0[i]))


def test_classical_play_properties():
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, 2000)
    r = np.linspace(0, 0.9, 7)
    f = play_outputs(u, r)
    # the output stays within the threshold band around the input
    assert np.all(np.abs(f - u[:, None]) <= r[None, :] + 1e-15)
    # initial loading from the relaxed state: F = max(0, u - r)
    ramp = np.linspace(0, 1, 101)
    np.testing.assert_allclose(play_outputs(ramp, r), np.maximum(0.0, ramp[:, None] - r))
    # rate independence: repeating every sample changes nothing at the originals
    np.testing.assert_array_equal(play_outputs(np.repeat(u, 3), r)[2::3], f)
    # r = 0 is the identity
    np.testing.assert_array_equal(f[:, 0], u)


def test_upi_operator_branches():
    # falling input follows the upper branch a (u + r), rising the lower u - r
    f = play_outputs(np.array([0.0, -0.5, -0.8, 0.9]), [0.1], a=0.5).ravel()
    np.testing.assert_allclose(f, [0.0, -0.2, -0.35, 0.8])


def test_play_outputs_rejects_bad_arguments():
    with pytest.raises(ValueError):
        play_outputs(np.zeros(3), [-0.1])
    with pytest.raises(ValueError):
        play_outputs(np.zeros(3), [0.1], a=0.0)
    with pytest.raises(ValueError):
        play_outputs(np.zeros(3), [0.1, 0.2], a=[1.0])
    with pytest.raises(ValueError):
        play_outputs(np.zeros((3, 2)), [0.1])


def test_play_outputs_on_a_long_drive_are_causal():
    # 300k samples, 40 unparallel plays. Its speed is measured by
    # tools/bench-diagnose-speed --kernels-only, not asserted here.
    u = 0.9 * np.sin(np.linspace(0, 200, 300_000))
    r, a = np.linspace(0, 0.9, 40), np.linspace(0.5, 1.5, 40)
    out = play_outputs(u, r, a=a)
    assert out.shape == (300_000, 40)
    np.testing.assert_array_equal(out[:5000], play_outputs(u[:5000], r, a=a))   # no sample sees the future


# ------------------------------------------------------------------ model and inverse


def test_cpi_inverse_params_by_hand():
    a0i, ri, bi = cpi_inverse_params(1.0, [0.0, 0.5], [1.0, 2.0])
    assert a0i == 1.0
    np.testing.assert_allclose(ri, [0.0, 1.0])
    np.testing.assert_allclose(bi, [-0.5, -0.25])


def test_cpi_only_forward_then_inverse_is_identity():
    rng = np.random.default_rng(2)
    p = EUPIParams(a0=0.4, r_cpi=np.sort(rng.uniform(0, 0.9, 10)), b=rng.uniform(0, 0.1, 10))
    u = np.clip(np.cumsum(rng.normal(0, 0.03, 5000)), -1, 1)
    y = eupi_model(u, p)
    np.testing.assert_allclose(eupi_inverse(y, p, u_range=None), u, atol=1e-12)
    # and the other way round: the model undoes the compensator
    yr = 0.5 * np.sin(np.linspace(0, 40, 5000)) * np.linspace(1, 0.2, 5000)
    np.testing.assert_allclose(eupi_model(eupi_inverse(yr, p, u_range=None), p), yr, atol=1e-12)
    # the inverse is itself a PI model: its loading thresholds ascend, weights <= 0
    _, ri, bi = cpi_inverse_params(p.a0, p.r_cpi, p.b)
    assert np.all(np.diff(ri) >= 0) and np.all(bi <= 0)


@pytest.mark.parametrize("use_kex", [False, True])
def test_full_eupi_inverse_error_is_one_step_change_of_g2(use_kex):
    p = geupi.reference_params()
    if use_kex:
        p = apply_kex(p, choose_kex(p, margin=0.2))
        assert p.k_ex > 0
    yr = _smooth_yr()
    u = eupi_inverse(yr, p, u_range=None)
    err = eupi_model(u, p) - yr
    # H[u](k) - yr(k) = G2(k) - G2(k-1) exactly, G2 = G_UPI + P - k_ex u
    base = EUPIParams(a0=1.0, r_cpi=np.zeros(0), b=np.zeros(0), r_upi=p.r_upi,
                      a_upi=p.a_upi, d=p.d, p=p.p, p0=p.p0)
    g2 = eupi_model(u, base) - u - p.k_ex * u
    np.testing.assert_allclose(err, np.diff(np.concatenate([[p.p0], g2])), atol=1e-12)
    # measured on this 10 Hz / 61 Hz signal at 10 kHz: 7.6e-4 FS (k_ex = 0),
    # 6.5e-4 FS (k_ex = 0.025), i.e. 25 and 21 q15 LSB
    assert np.max(np.abs(err)) < 8e-4


def test_apply_kex_leaves_the_model_alone():
    p = geupi.reference_params()
    u = gplay.realistic_drive(3000)
    np.testing.assert_array_equal(eupi_model(u, apply_kex(p, 0.3)), eupi_model(u, p))
    with pytest.raises(ValueError):
        apply_kex(p, -p.a0)


def test_poly_eval_horner():
    u = np.linspace(-1, 1, 11)
    np.testing.assert_allclose(poly_eval(u, 0.1, [0.2, -0.3, 0.4]),
                               0.1 + 0.2 * u**2 - 0.3 * u**3 + 0.4 * u**4)


# ------------------------------------------------------------------ small gain and k_ex


def test_slope_bounds_contain_every_difference_quotient():
    p = apply_kex(geupi.reference_params(), 0.1)
    lo, hi = slope_bounds(p)
    rng = np.random.default_rng(3)
    u = np.clip(np.concatenate([np.cumsum(rng.normal(0, 0.05, 20000)),
                                rng.uniform(-1, 1, 5000)]), -1, 1)
    base = EUPIParams(a0=1.0, r_cpi=np.zeros(0), b=np.zeros(0), r_upi=p.r_upi,
                      a_upi=p.a_upi, d=p.d, p=p.p, p0=p.p0)
    g2 = eupi_model(u, base) - u - p.k_ex * u
    du, dg = np.diff(u), np.diff(g2)
    q = dg[np.abs(du) > 1e-9] / du[np.abs(du) > 1e-9]
    assert q.min() >= lo - 1e-9 and q.max() <= hi + 1e-9
    # and the bound is not loose by more than the play part's worst case
    assert q.max() > hi - float(np.sum(p.d * np.maximum(1, p.a_upi)))


def test_small_gain_margin_formula():
    p = EUPIParams(a0=0.5, r_cpi=[0.0], b=[0.1], r_upi=[0.0, 0.5], a_upi=[0.5, 2.0],
                   d=[[0.01, 0.02], [0.03, 0.04]], p=[0.1], p0=0.0)
    # P' = 0.2 u in [-0.2, 0.2]; S = 0.01 + 0.04 + 0.03 + 0.08 = 0.16
    lo, hi = slope_bounds(p)
    assert lo == pytest.approx(-0.2) and hi == pytest.approx(0.36)
    assert small_gain_margin(p) == pytest.approx(0.5 - 0.36)
    assert small_gain_margin(p, 0.0, 0.5) == pytest.approx(0.5 - 0.26)


def test_choose_kex_reaches_the_margin_or_refuses():
    p = geupi.reference_params()
    assert choose_kex(p, margin=0.1) == 0.0                 # already fine
    k = choose_kex(p, margin=0.3)
    assert k > 0
    assert small_gain_margin(apply_kex(p, k)) == pytest.approx(0.3)
    assert small_gain_margin(apply_kex(p, 0.9 * k)) < 0.3   # smallest such k
    lo, _ = slope_bounds(p)
    with pytest.raises(ValueError):
        choose_kex(p, margin=p.a0 + lo + 0.01)              # above the plateau


def test_host_refuses_a_table_without_small_gain():
    p = geupi.reference_params()
    weak = EUPIParams(a0=0.05, r_cpi=p.r_cpi, b=p.b, r_upi=p.r_upi, a_upi=p.a_upi,
                      d=p.d * 3, p=p.p, p0=p.p0)
    assert small_gain_margin(weak) < 0
    with pytest.raises(ValueError, match="small-gain"):
        ginv.quantize_eupi_inv(weak)
    ok = apply_kex(weak, choose_kex(weak, margin=0.01))
    assert ginv.quantize_eupi_inv(ok, margin=0.0).kex_q24 > 0


# ------------------------------------------------------------------ golden models


def test_quantizers_raise_on_overflow():
    with pytest.raises(QOverflowError):
        gplay.quantize_bank([0.0, 40.0], None, [0.1, 0.1])            # beyond 32 FS
    with pytest.raises(QOverflowError):
        gplay.quantize_bank([0.0, 1.0], None, [0.1, 0.1], r_max_q15=32767)
    with pytest.raises(ValueError):
        gplay.quantize_bank([0.5, 0.1], None, [0.1, 0.1])             # descending
    with pytest.raises(ValueError):
        gplay.quantize_bank([0.1], [1e-9], [0.1])                      # slope -> 0
    with pytest.raises(QOverflowError):
        geupi.quantize_eupi(EUPIParams(a0=200.0, r_cpi=[0.0], b=[0.0]))
    with pytest.raises(QOverflowError):
        geupi.quantize_poly([40.0, -30.0], 0.0)                        # sum |p| > 64


def test_poly_sum_bound_is_strict():
    # round 18: sum |p_m| < 64 (eupi.h); exactly 64 is refused, one Q7.24
    # LSB less is accepted, and the golden Horner refuses a set beyond it
    with pytest.raises(QOverflowError, match="not below 64"):
        geupi.quantize_poly([40.0, -24.0], 0.0)
    p_q, _ = geupi.quantize_poly([40.0, -(24.0 - 2.0**-24)], 0.0)
    assert int(np.sum(np.abs(p_q))) == geupi.POLY_SUM_MAX_Q24 - 1
    geupi.poly_q39(p_q, 0, -32768)
    with pytest.raises(QOverflowError):
        geupi.poly_q39(np.array([1 << 30]), 0, 5)


def _smmulr(a, b):
    # SMMULR on int32 operands: the rounded high word of the 64-bit product
    assert np.all((a >= -2**31) & (a < 2**31)) and np.all((b >= -2**31) & (b < 2**31))
    return (a * b + (1 << 31)) >> 32


def test_horner_step_by_smmulr_is_exact_below_the_bound():
    # eupi.h's step rshift_rnd(h u, 15) as SMMULR(2 h, u 2^16): equal for
    # every q15 u and every |h| < 2^30 (sum |p_m| < 64 bounds |h|); at
    # h = 2^30, 2 h does not fit int32 and its wrap (-2^31) is wrong
    u = np.arange(-32768, 32768, dtype=np.int64)
    rng = np.random.default_rng(18)
    hs = [2**30 - 1, -(2**30 - 1), -(2**30), 1, -1, 0] + [int(x) for x in rng.integers(-2**30 + 1, 2**30, 20)]
    for h in hs:
        assert np.array_equal(_smmulr(np.int64(2 * h), u * 65536), fixed.rshift_rnd(h * u, 15)), h
    wrapped = _smmulr(np.int64(-(2**31)), u * 65536)        # 2 h for h = 2^30, wrapped
    assert not np.array_equal(wrapped, fixed.rshift_rnd((2**30) * u, 15))


def test_golden_play_bank_equals_float_on_exact_coefficients():
    # thresholds and input on the q15 grid, slopes powers of two: exact in
    # float, so the golden classical outputs equal play_outputs bit for bit
    # and the UPI outputs differ only by the rounding of a u (the thresholds
    # are even: a r is exact)
    rng = np.random.default_rng(4)
    u_q = rng.integers(-32768, 32768, 3000)
    r = np.array([0, 1024, 5000, 20000]) / 32768
    cpi = gplay.quantize_bank(r, None, [0.25, 0.5, 0.125, 1.0])
    f, _ = gplay.play_bank_run(cpi, u_q)
    np.testing.assert_array_equal(f / 32768, play_outputs(u_q / 32768, r))
    upi = gplay.quantize_bank(r, [0.5, 1.0, 2.0], np.full(12, 0.1))
    f, _ = gplay.play_bank_run(upi, u_q)
    ref = play_outputs(u_q / 32768, np.repeat(r, 3), np.tile([0.5, 1.0, 2.0], 4))
    assert np.max(np.abs(f - ref * 32768)) <= 0.5


def _upi_one_rounding(bank, u_q):
    """The UPI bank with the upper branch rounded once per operator,
    rshift_rnd(a (u + r), 24) (the golden model before round 17), operator by operator."""
    r, a = bank.per_op()
    f = np.zeros(r.size, dtype=np.int64)
    out = np.empty((len(u_q), r.size), dtype=np.int64)
    for k, u in enumerate(u_q):
        for i in range(r.size):
            hi = (int(a[i]) * (int(u) + int(r[i])) + (1 << 23)) >> 24
            f[i] = max(int(u) - int(r[i]), min(hi, int(f[i])))
        out[k] = f
    return out


def test_golden_upi_upper_branch_rounded_per_column():
    # round 17: hi = rshift_rnd(a u, 24) + rshift_rnd(a r, 24); every output
    # within one LSB of the one-rounding form, and the formula on every operator
    rng = np.random.default_rng(17)
    n_diff = 0
    for trial in range(6):
        n_r, n_a = int(rng.integers(1, 9)), int(rng.integers(1, 4))
        r = np.sort(rng.uniform(0.0, 0.95, n_r))
        a = rng.uniform(0.2, 2.5, n_a) + rng.integers(0, 2 ** 20, n_a) / 2.0 ** 24
        bank = gplay.quantize_bank(r, a, rng.uniform(-0.01, 0.01, n_r * n_a))
        u_q = np.clip(np.cumsum(rng.integers(-900, 901, 600)), -32768, 32767)
        f, acc = gplay.play_bank_run(bank, u_q)
        old = _upi_one_rounding(bank, u_q)
        assert np.max(np.abs(f - old)) <= 1
        n_diff += int(np.count_nonzero(f != old))
        rr, aa = bank.per_op()
        c = (aa * rr + (1 << 23)) >> 24
        fp = np.zeros(rr.size, dtype=np.int64)
        for k, u in enumerate(u_q):
            A = (aa * int(u) + (1 << 23)) >> 24
            fp = np.maximum(int(u) - rr, np.minimum(A + c, fp))
            np.testing.assert_array_equal(f[k], fp)
            assert acc[k] == int(fp @ bank.w_q24)
    assert n_diff > 0   # the two forms do differ somewhere: the test sees the change


def test_golden_poly_matches_float():
    p, p0 = [0.06, 0.03, -0.02], 0.015
    p_q, p0_q = geupi.quantize_poly(p, p0)
    u_q = np.arange(-32768, 32768, 7)
    got = geupi.poly_q39(p_q, p0_q, u_q) / 2.0**39
    assert np.max(np.abs(got - poly_eval(u_q / 32768, p0, p))) < 4 * 2.0**-24
    assert geupi.poly_q39(p_q, p0_q, 1234) == geupi.poly_q39(p_q, p0_q, np.array([1234]))[0]


def test_golden_runs_continue_from_state():
    q = geupi.quantize_eupi(geupi.reference_params())
    u = np.floor(gplay.realistic_drive(1200) * 32768 + 0.5).astype(np.int64)
    y1, st = geupi.eupi_run(q, u[:500], return_state=True)
    np.testing.assert_array_equal(np.concatenate([y1, geupi.eupi_run(q, u[500:], state=st)]),
                                  geupi.eupi_run(q, u))
    qi = ginv.quantize_eupi_inv(ginv.reference_inverse_params())
    u1, st = ginv.eupi_inv_run(qi, u[:500] // 2, return_state=True)
    np.testing.assert_array_equal(np.concatenate([u1, ginv.eupi_inv_run(qi, u[500:] // 2, state=st)]),
                                  ginv.eupi_inv_run(qi, u // 2))


def test_golden_inverse_clamps_and_model_undoes_it():
    qi = ginv.quantize_eupi_inv(ginv.reference_inverse_params())
    u = ginv.eupi_inv_run(qi, np.array([32767] * 50 + [-32768] * 50))
    assert u.max() == 32767 and u.min() == -32768
    # in range, the fixed-point model driven by the fixed-point inverse
    # reproduces a smooth yr within the float compensator's one-step error
    # (8e-4 FS above) plus a few LSB of fixed-point error; measured: 22 LSB
    yr_q = np.floor(_smooth_yr(6000) * 32768 + 0.5).astype(np.int64)
    u_q = ginv.eupi_inv_run(qi, yr_q)
    y_q = geupi.eupi_run(geupi.quantize_eupi(geupi.reference_params()), u_q)
    assert np.max(np.abs(y_q - yr_q)) < 8e-4 * 32768 + 3


@pytest.mark.parametrize("kernel", ["play", "eupi", "eupi_inv"])
def test_golden_tracks_float_within_documented_error(kernel):
    mod = {"play": gplay, "eupi": geupi, "eupi_inv": ginv}[kernel]
    rows = mod.error_report()
    assert rows
    for case, y_float, y_fixed in rows:
        assert len(y_float) == len(y_fixed) >= 10000
        mx, snr = error_stats(y_float, y_fixed)
        assert mx <= MAX_ERR_LSB[kernel], (case, mx)
        assert snr > 60.0, (case, snr)


@pytest.mark.parametrize("kernel", ["play", "eupi", "eupi_inv"])
def test_c_header_is_generated(kernel):
    mod = {"play": gplay, "eupi": geupi, "eupi_inv": ginv}[kernel]
    text = mod.c_header()
    assert f"PIEZO_GOLDEN_{kernel.upper()}_VECTORS_H" in text
    assert len(text) < 1_500_000


@pytest.mark.parametrize("modname", ["piezoctl.models.play", "piezoctl.models.eupi"])
def test_docstring_examples_run(modname):
    import doctest
    import importlib
    res = doctest.testmod(importlib.import_module(modname))
    assert res.attempted > 0 and res.failed == 0
