"""Cascade model: EUPI hysteresis then linear dynamics, on synthetic cascades."""

import json

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.ident import cascade as C
from piezoctl.ident import tf
from piezoctl.ident.common import IdentError, Options
from piezoctl.io.recording import Recording, save_recording
from piezoctl.models import eupi as E

TRUE_H = E.EUPIParams(a0=0.55, r_cpi=np.array([0.2, 0.4, 0.6]), b=np.array([0.15, 0.1, 0.05]),
                      r_upi=np.array([0.3]), a_upi=np.array([0.7]), d=np.array([[0.05]]),
                      p=np.array([0.05, -0.03]), p0=0.0)


def make_recordings(num, den, fs, f_top, seconds=2.0, seed=0):
    """Quasi-static sine (0.5 Hz) and an EUPI-inverse-processed chirp, through H then G."""
    def stage(v, t):
        return tf.simulate_tf(num, den, t, 50.0 + 40.0 * E.eupi_model(v, TRUE_H))
    rng = np.random.default_rng(seed)
    t1 = np.arange(int(2 * seconds * fs)) / fs
    v1 = 0.95 * np.sin(2 * np.pi * 0.5 * t1)
    t2 = np.arange(int(seconds * fs)) / fs
    ref = 0.8 * np.sin(2 * np.pi * (t2 + 0.5 * (f_top - 1.0) / seconds * t2 ** 2))
    kex = E.choose_kex(TRUE_H, -1, 1, margin=0.05)
    v2 = E.eupi_inverse(ref, E.apply_kex(TRUE_H, kex))
    return [Recording(t=t1, u=50 + 50 * v1, y=stage(v1, t1) + 0.01 * rng.standard_normal(t1.size)),
            Recording(t=t2, u=50 + 50 * v2, y=stage(v2, t2) + 0.01 * rng.standard_normal(t2.size))]


def sorted_poles(p):
    p = np.array([complex(*z) for z in p]) if np.ndim(p) == 2 else np.asarray(p)
    return p[np.lexsort((p.imag, p.real))]


def test_split_by_spectrum_and_by_index():
    wn = 2 * np.pi * 120
    recs = make_recordings([wn ** 2], [1, 2 * 0.3 * wn, wn ** 2], 2000.0, 250.0)
    assert C.spectral_centroid(recs[0].t, recs[0].u) == pytest.approx(0.5, abs=0.1)
    assert C.split_recordings(recs, Options()) == ([0], [1])
    assert C.split_recordings(recs, Options(cascade_static=[1])) == ([1], [0])
    with pytest.raises(IdentError):
        C.split_recordings([recs[1]], Options())


def test_recovers_second_order_dynamics():
    wn, z = 2 * np.pi * 120, 0.3
    den = [1, 2 * z * wn, wn ** 2]
    recs = make_recordings([wn ** 2], den, 2000.0, 250.0)
    p = C.fit(recs, Options(cascade_order=2, cascade_num_order=0, cascade_fmin=2.0, cascade_fmax=220.0,
                            cascade_refine=0, u_range=[0, 100]))
    assert p["static_files"] == [0] and p["dynamic_files"] == [1]
    np.testing.assert_allclose(sorted_poles(p["poles"]), sorted_poles(np.roots(den)), rtol=0.01)
    assert p["stable"]
    for r in recs:
        assert np.sqrt(np.mean((C.simulate(p, r.t, r.u) - r.y) ** 2)) < 0.01 * np.ptp(r.y)


def test_recovers_fourth_order_paper_dynamics_time_scaled():
    # the paper's actuator model with time scaled by 20 (poles x 20: 120 Hz and 470 Hz pairs)
    k = 20.0
    b = np.array([0.008933, -1.839, 260.4, 9.313e5, 3.096e7]) * k ** np.arange(0, 5)
    a = np.array([1, 244.2, 3.605e4, 1.898e6, 3.343e7]) * k ** np.arange(0, 5)
    dc = b[-1] / a[-1]
    recs = make_recordings(b / dc, a, 5000.0, 900.0, seconds=1.6)
    p = C.fit(recs, Options(cascade_order=4, cascade_fmin=3.0, cascade_fmax=600.0, cascade_refine=0,
                            u_range=[0, 100]))
    # The FRF estimate itself carries the EUPI fit's error (about 2 % median, 10 %
    # at worst off the continuous truth). The 120 Hz pair is nearly critically
    # damped (zeta = 0.96) and trades against the zeros: at this FRF quality it
    # comes out as a complex pair since pso-wcls refines (two real poles before) (measured: 193 and 844 rad/s for 751 +- 220j),
    # so only the 470 Hz pair and the response itself are checked.
    got, want = sorted_poles(p["poles"]), sorted_poles(np.roots(a))
    np.testing.assert_allclose(got[:2], want[:2], rtol=0.05)            # 470 Hz pair
    assert p["stable"]
    w = 2 * np.pi * np.array(p["frf"]["f_hz"])
    h_true = tf.freqresp(b / dc, a, w)
    assert np.median(np.abs(tf.freqresp(p["num"], p["den"], w) - h_true) / np.abs(h_true)) < 0.05


def test_joint_refinement_lowers_the_time_domain_error():
    wn, z = 2 * np.pi * 120, 0.3
    den = [1, 2 * z * wn, wn ** 2]
    recs = make_recordings([wn ** 2], den, 2000.0, 250.0, seconds=1.0)
    opts = dict(cascade_order=2, cascade_num_order=0, cascade_fmin=2.0, cascade_fmax=220.0,
                u_range=[0, 100], cascade_method="wcls")
    p0 = C.fit(recs, Options(opts, cascade_refine=0))
    p1 = C.fit(recs, Options(opts, cascade_refine=15))
    before, after = p1["refine_cost"]
    assert after < before
    sse = [sum(float(np.sum((C.simulate(p, r.t, r.u) - r.y) ** 2)) for r in recs) for p in (p0, p1)]
    assert sse[1] < sse[0]
    assert sse[1] == pytest.approx(after, rel=1e-6)
    assert p1["stable"]


def test_identify_cli_cascade(tmp_path):
    wn = 2 * np.pi * 120
    recs = make_recordings([wn ** 2], [1, 2 * 0.3 * wn, wn ** 2], 2000.0, 250.0, seconds=1.0)
    paths = []
    for i, r in enumerate(recs):
        save_recording(tmp_path / f"r{i}.csv", r)
        paths.append(str(tmp_path / f"r{i}.csv"))
    out = tmp_path / "m.json"
    rc = cli.main(["identify", "--model", "cascade", "--data", *paths, "--out", str(out),
                   "--cascade-num-order", "0", "--cascade-fmin", "2", "--cascade-fmax", "220",
                   "--cascade-refine", "0"])
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["kind"] == "cascade" and len(d["params"]["den"]) == 3
    assert all(re < 0 for re, _ in d["params"]["poles"])


def test_weights_step_refits_the_hysteresis_through_the_dynamics():
    """Variable projection, step a: with G fixed, wrong EUPI weights are refitted
    by linear least squares on the G-filtered operator outputs."""
    wn, z = 2 * np.pi * 120, 0.3
    den = [1, 2 * z * wn, wn ** 2]
    recs = make_recordings([wn ** 2], den, 2000.0, 250.0, seconds=1.0)
    opts = dict(cascade_order=2, cascade_num_order=0, cascade_fmin=2.0, cascade_fmax=220.0,
                u_range=[0, 100], cascade_method="wcls", cascade_refine=0)
    p = C.fit(recs, Options(opts))
    spoiled = json.loads(json.dumps(p, default=lambda o: np.asarray(o).tolist()))
    spoiled["hysteresis"]["b"] = [1.5 * v for v in spoiled["hysteresis"]["b"]]
    spoiled["hysteresis"]["a0"] *= 0.8
    step = C.refine_weights(spoiled, recs)
    before, after = step["refine_weights_cost"]
    assert after < 0.2 * before
    sse = sum(float(np.sum((C.simulate({**spoiled, **step}, r.t, r.u) - r.y) ** 2)) for r in recs)
    assert sse == pytest.approx(after, rel=1e-6)
    assert step["hysteresis"]["a0"] > 0 and min(step["hysteresis"]["b"]) >= 0
    assert step["hysteresis"]["invertible"]
