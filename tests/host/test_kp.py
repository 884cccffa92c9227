"""Tests of the KP kernel family on the host: the float64 reference
(piezoctl.models.kp) and the golden models (piezoctl.golden.kp/rkp/dcc)."""

from __future__ import annotations


import numpy as np
import pytest

from piezoctl import fixed
from piezoctl.fixed import Q15, Q16, Q24, QOverflowError
from piezoctl.golden import dcc as gdcc
from piezoctl.golden import kp as gkp
from piezoctl.golden import rkp as grkp
from piezoctl.golden.error_table import error_stats
from piezoctl.models import kp as fkp


# ------------------------------------------------------------ literal loops

def loop_kp(u, grid, psi0=None, u_prev=None):
    """The operator recursion written sample by sample, operator by operator."""
    psi = np.zeros(grid.N) if psi0 is None else np.array(psi0, dtype=float)
    up = grid.nmin if u_prev is None else u_prev
    out = np.empty((len(u), grid.N))
    for k, x in enumerate(u):
        for j in range(grid.N):
            if x > up:
                psi[j] = max(psi[j], min(max((x - grid.n2[j]) * grid.slope, 0.0), grid.nmax))
            elif x < up:
                psi[j] = min(psi[j], min(max((x - grid.n1[j]) * grid.slope, 0.0), grid.nmax))
        out[k] = psi
        up = x
    return out


def loop_kp_q(u, g: gkp.KPGridQ):
    """The integer recursion of kp.c, sample by sample, with Python ints."""
    def r(x):
        return min(g.rmax, fixed.rshift_rnd(max(x, 0) * g.slope, 16))
    psi = [0] * g.N
    up = g.nmin
    out = []
    for x in (int(v) for v in u):
        for j in range(g.N):
            if x > up:
                psi[j] = max(psi[j], r(x - int(g.n2[j])))
            elif x < up:
                psi[j] = min(psi[j], r(x - int(g.n1[j])))
        out.append(list(psi))
        up = x
    return np.array(out, dtype=np.int64)


def rich_signal(T, seed=0):
    """Random walk with reversals, holds (repeated samples) and large jumps, in [-1, 1)."""
    rng = np.random.default_rng(seed)
    u = np.cumsum(rng.standard_normal(T) * 0.05)
    u = 0.98 * np.sin(u)
    u[rng.integers(0, T, T // 10)] = rng.uniform(-1, 1, T // 10)
    hold = rng.integers(1, T, T // 8)
    u[hold] = u[hold - 1]
    return u


# ------------------------------------------------------------------- grid

def test_grid_cells_are_the_midpoints_of_the_triangle():
    g = fkp.kp_grid(10, -1.0, 1.0)
    assert g.N == 55 and g.L == 10
    h = 0.2
    mids = -1.0 + (np.arange(10) + 0.5) * h
    pairs = {(round(a, 12), round(b, 12)) for a, b in zip(g.n1, g.n2)}
    want = {(round(mids[i], 12), round(mids[j], 12)) for i in range(10) for j in range(i, 10)}
    assert pairs == want
    assert np.all(g.n1 <= g.n2)
    assert g.s == pytest.approx(2.0 / 9.0)       # paper's 1/(L-1) on a unit-width plane
    assert g.slope == pytest.approx(4.5)
    # row by row numbering: first the L cells with n1 at the lowest midpoint
    assert np.all(g.n1[:10] == mids[0]) and np.allclose(g.n2[:10], mids)


@pytest.mark.parametrize("args", [(0,), (3, 1.0, -1.0), (3, -1.0, 0.0), (3, -1.0, 1.0, 0.0)])
def test_grid_refuses_bad_arguments(args):
    with pytest.raises(ValueError):
        fkp.kp_grid(*args)


# ------------------------------------------------------------ KP operators

def test_vectorized_operators_equal_the_literal_loop_exactly():
    g = fkp.kp_grid(6)
    rng = np.random.default_rng(1)
    for u, psi0, up in ((rich_signal(1500, 2), None, None),
                        (rng.uniform(-1, 1, 800), rng.uniform(0, 1, g.N), 0.3),
                        (np.repeat(rng.uniform(-1, 1, 40), 7), None, -0.2)):
        np.testing.assert_array_equal(fkp.kp_outputs(u, g, psi0, up), loop_kp(u, g, psi0, up))


def test_operators_follow_the_input_monotonically_and_stay_in_range():
    g = fkp.kp_grid(8)
    up = np.linspace(-1, 1, 400)
    down = up[::-1]
    psi = fkp.kp_outputs(np.concatenate([up, down]), g)
    assert np.all(np.diff(psi[:400], axis=0) >= 0)
    assert np.all(np.diff(psi[400:], axis=0) <= 0)
    assert psi.min() >= 0.0 and psi.max() <= g.nmax
    # at the top, every cell whose ramp [n2, n2 + s] ends below it is saturated;
    # back at the bottom (u = nmin <= n1) every operator is 0 again
    full = g.n2 + g.s <= 1.0
    assert full.sum() > g.N // 2 and np.all(psi[399][full] == g.nmax)
    assert np.all(psi[399][~full] < g.nmax)
    assert np.all(psi[-1] == 0.0)


def test_operators_are_rate_independent():
    """Repeating samples (a slower input) does not change the operators' path."""
    g = fkp.kp_grid(5)
    u = rich_signal(600, 3)
    slow = np.repeat(u, 3)
    np.testing.assert_array_equal(fkp.kp_outputs(slow, g)[2::3], fkp.kp_outputs(u, g))


def test_operators_show_hysteresis_between_n1_and_n2():
    g = fkp.kp_grid(4, s=0.01)
    j = int(np.argmax(g.n2 - g.n1))              # widest loop: n1 = -0.75, n2 = 0.75
    up = np.linspace(-1, 1, 2001)
    psi = fkp.kp_outputs(np.concatenate([up, up[::-1]]), g)[:, j]
    mid = np.abs(up) < 0.5
    assert np.all(psi[:2001][mid] == 0.0)        # still low on the way up
    assert np.all(psi[2001:][mid[::-1]] == g.nmax)  # still high on the way down


def test_model_reproduces_a_known_density():
    g = fkp.kp_grid(7)
    u = rich_signal(5000, 4)
    rng = np.random.default_rng(5)
    w = rng.uniform(0, 1, g.N)
    P = fkp.kp_outputs(u, g)
    y = fkp.kp_model(u, g, w)
    np.testing.assert_allclose(y, P @ w, rtol=0, atol=1e-12)
    w_hat, *_ = np.linalg.lstsq(P, y, rcond=None)
    np.testing.assert_allclose(w_hat, w, atol=1e-8)
    # one cell's density alone gives that operator's output
    e = np.zeros(g.N)
    e[11] = 1.0
    np.testing.assert_array_equal(fkp.kp_model(u, g, e), P[:, 11])


def test_kp_outputs_on_a_long_noisy_drive_are_causal_and_bounded():
    # 300k samples (30 s at 10 kHz) with noise: every sample a small reversal. Its speed is
    # measured by tools/bench-diagnose-speed --kernels-only, not asserted here.
    g = fkp.kp_grid(10)
    t = np.arange(300_000) * 1e-4
    u = 0.9 * np.sin(2 * np.pi * 7 * t) + 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    out = fkp.kp_outputs(u, g)
    assert out.shape == (300_000, 55)
    assert np.all(np.abs(out) <= 1.0)
    np.testing.assert_array_equal(out[:5000], fkp.kp_outputs(u[:5000], g))   # no sample sees the future


# -------------------------------------------------- compensation operators

def test_psi_plus_compensation_is_the_input():
    g = fkp.kp_grid(9)
    rng = np.random.default_rng(6)
    for u, psi0, up in ((rich_signal(3000, 7), None, None),
                        (rich_signal(2000, 8), None, 0.1)):
        P = fkp.kp_outputs(u, g, psi0, up)
        C = fkp.kp_compensation_outputs(u, g, psi0, up)
        np.testing.assert_allclose(P + C, np.broadcast_to(u[:, None], P.shape), rtol=0, atol=1e-12)
    psi0 = fkp.kp_outputs(rng.uniform(-1, 1, 50), g)[-1]          # a reachable state
    u = rich_signal(500, 9)
    up = 0.2
    P = fkp.kp_outputs(u, g, psi0, up)
    C = fkp.kp_compensation_outputs(u, g, psi0, up)
    np.testing.assert_allclose(P + C, np.broadcast_to(u[:, None], P.shape), rtol=0, atol=1e-12)


def test_golden_psi_plus_compensation_is_the_input_exactly():
    gq = gkp.quantize_grid(fkp.kp_grid(10))
    for u in gkp.golden_cases().values():
        np.testing.assert_array_equal(gkp.kp_outputs_q(u, gq) + gdcc.comp_outputs_q(u, gq),
                                      np.broadcast_to(u[:, None], (u.size, gq.N)))


def test_dcc_law_inverts_the_model_up_to_the_one_step_delay():
    """y(u[k]) - yd[k] = (Psi(u[k-1]) - Psi(u[k])) . w, bounded by sum|w| (1 + slope) |du|."""
    g = fkp.kp_grid(10)
    w = gkp.demo_density(g)
    t = np.arange(20000) * 1e-4
    yd = 0.5 + 0.35 * np.sin(2 * np.pi * 3 * t) * np.exp(-t) + 0.05 * np.sin(2 * np.pi * 40 * t)
    u = fkp.dcc_law(yd, g, w)
    assert u.min() > -1.0 and u.max() < 1.0                       # clipping inactive
    y = fkp.kp_model(u, g, w)
    du = np.abs(np.diff(u, prepend=g.nmin))
    bound = np.sum(np.abs(w)) * (1.0 + g.slope) * du + 1e-12
    err = np.abs(y - yd)
    assert np.all(err <= bound)
    assert np.max(err[100:]) < 0.01                               # tracks to 1 % FS


def test_dcc_gain_refuses_a_non_positive_density():
    with pytest.raises(ValueError):
        fkp.dcc_gain(np.array([0.5, -0.5]))


# -------------------------------------------------------------------- RKP

def test_rate_estimate_of_a_ramp_and_its_filter():
    dt = 1e-4
    u = np.linspace(-0.5, 0.5, 1001)                 # 1 FS over 0.1 s: 10 FS/s
    r = fkp.rate_estimate(u, dt)                    # default u_prev = u[0]: no initial step
    assert r[0] == 0.0
    np.testing.assert_allclose(r[1:], 10.0, rtol=1e-9)
    a = fkp.lowpass_coefficient(200.0, dt)
    r = fkp.rate_estimate(u, dt, a, u_prev=u[0] - 1e-3)   # filtered from rate 0
    assert r[0] == pytest.approx(a * 10.0)
    assert r[-1] == pytest.approx(10.0, rel=1e-6)
    assert np.all(np.diff(r) >= -1e-9)
    with pytest.raises(ValueError):
        fkp.rate_estimate(u, dt, 0.0)


def test_rate_features_peak_at_the_matching_center():
    dt = 1e-4
    centers = np.linspace(-600, 600, 13)
    u = np.linspace(-50.0, 50.0, 5001)               # 100 FS in 0.5 s: 200 FS/s
    F = fkp.rate_features(u, dt, centers, np.full(13, 100.0))
    assert np.all(np.argmax(F[10:], axis=1) == 8)                      # center 200
    assert F[100, 8] == pytest.approx(1.0)
    assert F[100, 9] == pytest.approx(np.exp(-0.5))


def test_rkp_with_a_flat_rate_basis_is_the_kp_model():
    g = fkp.kp_grid(6)
    w = gkp.demo_density(g)
    u = rich_signal(2000, 10)
    y = fkp.rkp_model(u, g, w[:, None], 1e-4, [0.0], [1e12])
    np.testing.assert_allclose(y, fkp.kp_model(u, g, w), rtol=0, atol=1e-12)


def test_rkp_density_follows_the_rate():
    g = fkp.kp_grid(4)
    theta = np.zeros((g.N, 2))
    theta[:, 0] = 1.0                                 # slow Gaussian
    theta[:, 1] = 2.0                                 # fast Gaussian
    t = np.arange(4000) * 1e-4
    slow = -0.9 + 0.1 * t                             # 0.1 FS/s
    fast = -0.9 + 4.0 * t                             # 4 FS/s (up to 0.7)
    kw = dict(dt=1e-4, centers=[0.0, 4.0], widths=[0.5, 0.5], u_prev=-0.9)
    ys = fkp.rkp_model(slow, g, theta, **kw)
    yf = fkp.rkp_model(fast, g, theta, **kw)
    ks = fkp.kp_model(slow, g, np.ones(g.N), u_prev=-0.9)
    kf = fkp.kp_model(fast, g, np.ones(g.N), u_prev=-0.9)
    np.testing.assert_allclose(ys[1:], ks[1:] * np.exp(-0.5 * (0.1 / 0.5) ** 2), rtol=1e-9)
    np.testing.assert_allclose(yf[1:], kf[1:] * 2.0, rtol=1e-9)


# ------------------------------------------------------------- golden: KP

def test_golden_kp_vectorized_equals_the_integer_loop():
    g = fkp.kp_grid(5)
    gq = gkp.quantize_grid(g)
    for name, u in gkp.golden_cases(600).items():
        np.testing.assert_array_equal(gkp.kp_outputs_q(u, gq), loop_kp_q(u, gq), err_msg=name)
    ge, _ = gkp.edge_grid()
    u = gkp.golden_cases(600)["random"]
    np.testing.assert_array_equal(gkp.kp_outputs_q(u, ge), loop_kp_q(u, ge))


def test_quantized_grid_fields():
    g = fkp.kp_grid(10)
    gq = gkp.quantize_grid(g)
    assert gq.rmax == 32767                        # nmax = 1.0 stored at the q15 top
    assert gq.slope == round(4.5 * 65536) and gq.nmin == -32768
    assert fixed.rshift_rnd(gq.xsat * gq.slope, 16) >= gq.rmax
    assert fixed.rshift_rnd((gq.xsat - 1) * gq.slope, 16) < gq.rmax
    np.testing.assert_array_equal(gq.n1, fixed.to_q(g.n1, Q15))


def test_quantizers_raise_on_overflow():
    with pytest.raises(QOverflowError):
        gkp.quantize_density([0.5, 200.0])
    with pytest.raises(QOverflowError):
        gkp.quantize_grid(fkp.kp_grid(4, -1.0, 1.5))
    with pytest.raises(QOverflowError):
        gkp.quantize_grid(fkp.kp_grid(4, -1.5, 1.0))
    grid, theta, c, w, f = grkp.std_model()
    with pytest.raises(QOverflowError):             # 1/(sigma dt) beyond q16
        grkp.quantize(grid, theta, 1e-4, c, np.full(13, 0.1), f)
    with pytest.raises(QOverflowError):             # a center beyond 4 FS per sample
        grkp.quantize(grid, theta, 1e-4, np.linspace(-5e4, 5e4, 13), w, f)
    with pytest.raises(QOverflowError):             # sum_m |theta| beyond q24
        grkp.quantize(grid, np.full_like(theta, 20.0), 1e-4, c, w, f)
    with pytest.raises(QOverflowError):
        gdcc.quantize(grid, np.full(grid.N, 1e-4), gain=300.0)


def test_golden_kp_tracks_the_float_reference_within_the_documented_bound():
    grid, gq, w, wq = gkp.std_grid()
    bound = gkp.error_bound_lsb(grid, gq, w, wq)
    assert bound < 5.0
    for name, yf, yq in gkp.error_report():
        mx, snr = error_stats(yf, yq)
        assert mx <= bound, name
        assert snr > 80.0, name
    u = fixed.to_q(rich_signal(5000, 11), Q15)
    yf = fkp.kp_model(u / Q15.one, grid, w)
    yq, _ = gkp.kp_process_q(u, gq, wq)
    assert error_stats(yf, yq)[0] <= bound


# ------------------------------------------------------------ golden: RKP

def test_gaussian_lut_interpolation_error():
    z = np.arange(0, grkp.ZMAX_Q16 + 3000, 7, dtype=np.int64)
    exact = np.exp(-0.5 * (z / 65536.0) ** 2) * 32768.0
    got = grkp.gauss_q(z)
    inside = z < grkp.ZMAX_Q16
    # LUT rounding 0.5 + interpolation (step 2^-6)^2 / 8 * max|g''| = 1.0 + rounding 0.5
    assert np.max(np.abs(got[inside] - exact[inside])) <= 2.0
    assert np.all(got[~inside] == 0)
    assert np.max(exact[~inside]) <= np.exp(-8.0) * 32768.0 + 1e-9
    assert np.all(np.diff(got) <= 0)                 # non-increasing in z


def test_golden_rate_filter_tracks_the_float_filter():
    """Same coefficient: each step's rounding (<= 0.5 LSB q24) decays at (1 - a)."""
    u = fixed.to_q(rich_signal(4000, 12) * 0.5, Q15)
    for alpha in (65536, 17723, 655, 1):
        a = alpha / 65536.0
        rq = grkp.rate_q(u, alpha, u_prev=int(u[0]))
        rf = fkp.rate_estimate(u / Q15.one, 1.0, a)
        assert np.max(np.abs(rq / Q24.one - rf)) * Q24.one <= 0.5 / a + 1e-6


def test_golden_rkp_tracks_the_float_reference():
    """Bound: operators as KP; features: LUT (2 LSB) + cut at zmax (exp(-8)) +
    the slope of g (<= e^-1/2) times the z error from the rate filter's
    rounding (0.5/a LSB q24), its coefficient's rounding and the centers'."""
    grid, theta, c, sg, filt = grkp.std_model()
    r = grkp.quantize(grid, theta, grkp.DT, c, sg, filt)
    for name, yf, yq in grkp.error_report():
        u = gkp.realistic_signal(20000, seed=11)
        a = r.alpha / 65536.0
        d = np.diff(u / Q15.one, prepend=grid.nmin)
        qf = fkp.rate_estimate(u / Q15.one, 1.0, filt, grid.nmin)
        e_rate = (0.5 / Q24.one + abs(a - filt) * np.max(np.abs(d - qf))) / a + 0.5 / Q24.one
        e_z = np.max(r.inv_width / Q16.one) * e_rate + 0.5 / Q16.one
        e_f = (2.0 + np.exp(-8.0) * Q15.one + np.exp(-0.5) * e_z * Q15.one) / Q15.one
        th_q = r.theta.T / Q24.one
        e_w = np.sum(np.abs(theta), axis=1) * e_f + np.sum(np.abs(th_q - theta), axis=1) + 2.0 ** -24
        w_max = np.sum(np.abs(theta), axis=1)
        e_psi = 0.5 * grid.slope + 2.0 + abs(r.grid.rmax - Q15.one)
        bound = np.sum(w_max * e_psi) + np.sum(e_w) * Q15.one + 0.5
        mx, snr = error_stats(yf, yq)
        assert mx <= bound, (name, mx, bound)
        assert snr > 70.0


# ------------------------------------------------------------ golden: DCC

def test_golden_dcc_matches_the_float_law_step_by_step():
    """Each fixed drive u_q[k] against the float law evaluated on the fixed
    trajectory (no feedback amplification): the operators' error (as KP) times
    sum|g w|, the coefficients' rounding and the final rounding."""
    grid, w = gdcc.std_model()
    d = gdcc.quantize(grid, w)
    g = fkp.dcc_gain(w)
    for name, yd in (("realistic", gdcc._realistic_yd(6000, 21)),
                     ("random", gkp.golden_cases(3000)["random"])):
        uq = gdcc.dcc_process_q(yd, d)
        v = np.concatenate([[grid.nmin], uq[:-1] / Q15.one])   # operators see u[k-1]
        C = fkp.kp_compensation_outputs(v, grid)
        uf1 = np.clip(g * (yd / Q15.one) + C @ (g * w), -1.0, 1.0 - 2 ** -15)
        e_psi = 0.5 * grid.slope + 2.0 + abs(d.grid.rmax - Q15.one)
        e_c = np.abs(d.c / Q24.one - g * w)
        bound = (np.sum(np.abs(g * w)) * e_psi + np.max(np.abs(C)) * np.sum(e_c) * Q15.one
                 + abs(d.g / Q24.one - g) * np.max(np.abs(yd)) + 0.5)
        err = np.max(np.abs(uq - uf1 * Q15.one))
        assert err <= bound, (name, err, bound)
    for name, uf, uq in gdcc.error_report():
        mx, snr = error_stats(uf, uq)
        assert snr > 70.0, name


def test_golden_dcc_refuses_bad_gain():
    grid, w = gdcc.std_model()
    with pytest.raises(ValueError):
        gdcc.quantize(grid, -w)


def test_c_headers_are_generated():
    for mod, marker in ((gkp, "KP_GOLDEN_CASES"), (grkp, "RKP_GOLDEN_CASES"),
                        (gdcc, "DCC_GOLDEN_CASES")):
        text = mod.c_header()
        assert marker in text
        assert len(text) < 600_000
