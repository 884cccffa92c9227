"""Laguerre filters and the distributed Hammerstein cross-coupling model."""

import json
import math

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.ident import get_kind
from piezoctl.ident import hammerstein as H
from piezoctl.ident.common import Options
from piezoctl.ident.laguerre import laguerre_ab, laguerre_filter, laguerre_rhos
from piezoctl.io.recording import Recording, save_recording


def test_laguerre_ab_against_the_formulas():
    q, T, m = 0.1, 2.0, 4
    r1 = math.exp(-q * T)
    r2 = T + 2 / q * (r1 - 1)
    r3 = -T * r1 - 2 / q * (r1 - 1)
    r4 = math.sqrt(2 * q) * (1 - r1) / q
    assert laguerre_rhos(q, T) == pytest.approx((r1, r2, r3, r4), rel=1e-15)
    a, b = laguerre_ab(m, q, T)
    for i in range(1, m + 1):
        for j in range(1, m + 1):
            if i == j:
                want = r1
            elif i > j:
                want = (-1) ** (i - j - 1) * r2 ** (i - j - 1) * (r1 * r2 + r3) / T ** (i - j)
            else:
                want = 0.0
            assert a[i - 1, j - 1] == pytest.approx(want, rel=1e-14, abs=1e-300)
    np.testing.assert_allclose(b, [r4 * (-r2 / T) ** k for k in range(m)], rtol=1e-14)
    # the paper's settings: m = 2, q = 0.1, T = 2
    a2, b2 = laguerre_ab(2, 0.1, 2.0)
    assert a2[0, 0] == pytest.approx(math.exp(-0.2)) and a2[0, 1] == 0.0
    with pytest.raises(ValueError):
        laguerre_ab(0, 0.1, 2.0)


def test_laguerre_filter_is_the_state_recursion():
    a, b = laguerre_ab(3, 0.1, 2.0)
    mu = 2.0 + np.random.default_rng(1).standard_normal(200)
    z = np.linalg.solve(np.eye(3) - a, b * mu[0])  # steady state of mu[0]
    want = []
    for k in range(mu.size):
        want.append(z.copy())
        z = a @ z + b * mu[k]
    np.testing.assert_allclose(laguerre_filter(mu, 3, 0.1, 2.0), np.array(want), atol=1e-11)
    # zero initial state, and several columns at once
    z = np.zeros(3)
    want0 = []
    for k in range(mu.size):
        want0.append(z.copy())
        z = a @ z + b * mu[k]
    out = laguerre_filter(np.column_stack([mu, 2 * mu]), 3, 0.1, 2.0, steady=False)
    np.testing.assert_allclose(out[:, :, 0], np.array(want0), atol=1e-11)
    np.testing.assert_allclose(out[:, :, 1], 2 * np.array(want0), atol=1e-11)


def test_input_and_position_bases():
    un = np.array([-1.0, 0.0, 0.5])
    g = H.input_basis(un, [0, 1, 2, 3, 7], 5)
    assert g.shape == (3, 15)
    np.testing.assert_allclose(g[:, 4], un ** 7)
    np.testing.assert_allclose(g[:, 5 + 4], np.sin(5 * un))
    np.testing.assert_allclose(g[:, 10], np.cos(un))
    r = H.poly_basis(un, 7)
    assert r.shape == (3, 8)
    np.testing.assert_allclose(r[:, 3], un ** 3)


SETTINGS = dict(m=2, q=0.1, T=2.0, powers=[0, 1, 2, 3], harmonics=1)
NORM = dict(u_center=4.0, u_scale=5.0, x_center=120.0, x_scale=120.0)


def drive(n, seed):
    rng = np.random.default_rng(seed)
    v = np.convolve(rng.standard_normal(n), np.ones(6) / 6, "same") / 0.45
    return 4.0 + 5.0 * np.clip(v, -1, 1)


def true_channels(rng, degree, nc):
    nfun = len(SETTINGS["powers"]) + 2 * SETTINGS["harmonics"]
    return [{"eta": rng.standard_normal((nfun, degree + 1)).tolist(),
             "xi": rng.standard_normal((SETTINGS["m"], degree + 1)).tolist()} for _ in range(nc)]


def test_recovers_position_independent_two_channel_model_exactly():
    rng = np.random.default_rng(0)
    truth = dict(SETTINGS, **NORM, degree=0, channels_fit=true_channels(rng, 0, 2))
    us = [drive(700, s) for s in range(3)]
    xs = [np.full(700, 120.0)] * 3
    ys = [H.predict(truth, u, x) for u, x in zip(us, xs)]
    fit = H.fit_arrays(us, xs, ys, degree=0, channels=2, refine=0, **SETTINGS)
    assert len(fit["channels_fit"]) == 2
    sig = np.array(fit["sigma"])
    assert sig.size == 2 and sig[1] > 1e-3 * sig[0]  # Theta is 2 x 6 here, of full rank 2
    uv = drive(700, 99)
    yv = H.predict(truth, uv, 120.0)
    assert np.max(np.abs(H.predict(fit, uv, 120.0) - yv)) < 1e-8 * np.ptp(yv)
    # one channel is not enough for a rank-2 truth
    fit1 = H.fit_arrays(us, xs, ys, degree=0, channels=1, refine=0, **SETTINGS)
    assert np.max(np.abs(H.predict(fit1, uv, 120.0) - yv)) > 1e-2 * np.ptp(yv)


def test_position_dependent_model_full_solution_and_refined_channel():
    rng = np.random.default_rng(2)
    truth = dict(SETTINGS, **NORM, degree=2, channels_fit=true_channels(rng, 2, 1))
    pos = [0.0, 60.0, 120.0, 180.0, 240.0]
    us = [drive(700, s) for s in range(len(pos))]
    xs = [np.full(700, p) for p in pos]
    ys = [H.predict(truth, u, x) for u, x in zip(us, xs)]
    paper = H.fit_arrays(us, xs, ys, degree=2, channels=1, refine=0, **SETTINGS)
    refined = H.fit_arrays(us, xs, ys, degree=2, channels=1, refine=20, **SETTINGS)
    uv = drive(700, 77)
    for p in (30.0, 150.0, 240.0):
        yv = H.predict(truth, uv, p)
        span = np.ptp(yv)
        # the full least-squares solution is exact, also between the training positions
        assert np.max(np.abs(H.predict(paper, uv, p, full=True) - yv)) < 1e-6 * span
        # the refined single channel is close; the bare SVD split is far worse
        e_ref = np.max(np.abs(H.predict(refined, uv, p) - yv)) / span
        e_svd = np.max(np.abs(H.predict(paper, uv, p) - yv)) / span
        assert e_ref < 5e-3
        assert e_svd > 10 * e_ref
    rss = refined["refine_rss"]
    assert all(b < a for a, b in zip(rss, rss[1:]))


def test_time_varying_position_is_consistent_between_fit_and_predict():
    rng = np.random.default_rng(4)
    truth = dict(SETTINGS, **NORM, degree=2, channels_fit=true_channels(rng, 2, 1))
    n = 900
    us = [drive(n, s) for s in range(3)]
    xs = [120 + 110 * np.sin(np.arange(n) / 60.0 + s) for s in range(3)]
    ys = [H.predict(truth, u, x) for u, x in zip(us, xs)]
    fit = H.fit_arrays(us, xs, ys, degree=2, channels=1, refine=0, **SETTINGS)
    uv, xv = drive(n, 50), 120 + 100 * np.cos(np.arange(n) / 45.0)
    yv = H.predict(truth, uv, xv)
    # (Gram-moment accumulation loses some digits; an x taken after instead of
    # before the filters would be off by ~0.1 of the span here)
    assert np.max(np.abs(H.predict(fit, uv, xv, full=True) - yv)) < 1e-4 * np.ptp(yv)


def _recordings(truth, pos, n=600):
    recs = []
    for k, p in enumerate(pos):
        u2 = drive(n, 10 + k)
        t = np.arange(n) * 1e-4
        recs.append(Recording(t=t, u=np.zeros(n), y=H.predict(truth, u2, p), u2=u2, x2=np.full(n, p)))
    return recs


def test_kind_interface_fit_and_simulate():
    kind = get_kind("hammerstein")
    assert kind.KIND == "hammerstein"
    rng = np.random.default_rng(5)
    truth = dict(SETTINGS, **NORM, degree=1, channels_fit=true_channels(rng, 1, 1))
    recs = _recordings(truth, [0.0, 80.0, 160.0, 240.0])
    opts = Options(hammerstein_degree=1, hammerstein_powers=[0, 1, 2, 3], hammerstein_harmonics=1,
                   hammerstein_channels=1)
    params = kind.fit(recs, opts)
    assert params["position_source"] == "x2"
    json.dumps(params)  # JSON-serializable
    r = recs[1]
    y = kind.simulate(params, r.t, r.u, r.u2, x2=r.x2)
    assert np.max(np.abs(y - r.y)) < 1e-3 * np.ptp(r.y)
    # without positions the mean training position is used
    y_mean = kind.simulate(params, r.t, r.u, r.u2)
    np.testing.assert_allclose(y_mean, kind.simulate(params, r.t, r.u, r.u2, x2=np.full(r.t.size, 120.0)))
    with pytest.raises(ValueError):
        kind.simulate(params, r.t, r.u)


def test_kind_needs_u2():
    from piezoctl.ident.common import IdentError
    r = Recording(t=np.arange(10) * 1e-3, u=np.arange(10.0), y=np.zeros(10))
    with pytest.raises(IdentError, match="u2"):
        H.fit([r], Options())


def test_identify_cli_writes_hammerstein_model(tmp_path):
    rng = np.random.default_rng(6)
    truth = dict(SETTINGS, **NORM, degree=1, channels_fit=true_channels(rng, 1, 1))
    paths = []
    for k, rec in enumerate(_recordings(truth, [0.0, 120.0, 240.0], n=400)):
        p = tmp_path / f"c{k}.csv"
        save_recording(p, rec)
        paths.append(str(p))
    out = tmp_path / "m.json"
    rc = cli.main(["identify", "--model", "hammerstein", "--data", *paths, "--out", str(out),
                   "--hammerstein-degree", "1", "--hammerstein-powers", "0", "1", "2", "3",
                   "--hammerstein-harmonics", "1", "--hammerstein-channels", "1"])
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["kind"] == "hammerstein"
    assert d["params"]["degree"] == 1 and len(d["params"]["channels_fit"]) == 1
