"""Identification: parameters recovered from synthetic data made with the float
reference models, the RKP online law, CLI contracts of identify/simulate, and a
bound on real-data NRMSE (piezoctl.ident.*, piezoctl.commands.identify/simulate)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.ident import MODEL_KINDS, eupi, kp, preisach, rkp
from piezoctl.ident.common import Options, nrmse
from piezoctl.io.modelfile import load_model
from piezoctl.io.recording import Recording, load_recording, save_recording
from piezoctl.models import eupi as eupiref
from piezoctl.models import kp as kpref
from piezoctl.models.play import play_outputs

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"


def rich_drive(T=6000, dt=1e-3, seed=0):
    """Normalized drive with many reversal amplitudes and rates, in [-1, 1]."""
    t = np.arange(T) * dt
    env = 0.55 + 0.45 * np.cos(2 * np.pi * 0.37 * t)
    v = env * np.sin(2 * np.pi * (1.3 * t + 0.8 * t ** 2 / t[-1])) + 0.05 * np.sin(2 * np.pi * 7.1 * t)
    v = v / np.max(np.abs(v))
    return t, v


def as_recording(t, u, y):
    return Recording(t=np.asarray(t, float), u=np.asarray(u, float), y=np.asarray(y, float))


# --------------------------------------------------------------------- kp

def test_kp_recovers_density_linear_term_and_offset():
    t, v = rich_drive()
    u = 75.0 + 75.0 * v                       # 0..150 V, normalization maps it back to v
    grid = kpref.kp_grid(5)
    rng = np.random.default_rng(1)
    w = rng.uniform(0.0, 2.0, grid.N) * (rng.uniform(size=grid.N) > 0.3)
    y = kpref.kp_model(v, grid, w) + 1.5 * v - 3.0
    params = kp.fit([as_recording(t, u, y)], Options(kp_levels=5, u_range=[0.0, 150.0]))
    assert params["N"] == grid.N
    np.testing.assert_allclose(params["w"], w, atol=1e-6)
    assert params["linear"] == pytest.approx(1.5, abs=1e-6)
    assert params["offset"] == pytest.approx(-3.0, abs=1e-6)
    assert nrmse(y, kp.simulate(params, t, u)) < 1e-8


def test_kp_density_is_non_negative_unless_signed():
    t, v = rich_drive()
    grid = kpref.kp_grid(4)
    w = np.linspace(-1.0, 1.0, grid.N)        # not a physical density
    y = kpref.kp_model(v, grid, w)
    rec = as_recording(t, v, y)
    constrained = kp.fit([rec], Options(kp_levels=4, kp_linear="off", u_range=[-1, 1]))
    assert np.min(constrained["w"]) >= 0.0
    assert nrmse(y, kp.simulate(constrained, t, v)) > 1e-3     # cannot reproduce negative weights
    signed = kp.fit([rec], Options(kp_levels=4, kp_linear="off", kp_signed=True, u_range=[-1, 1]))
    np.testing.assert_allclose(signed["w"], w, atol=1e-6)


def test_per_file_offsets():
    t, v = rich_drive(T=3000)
    grid = kpref.kp_grid(3)
    w = np.arange(1.0, grid.N + 1)
    y = kpref.kp_model(v, grid, w)
    recs = [as_recording(t, v, y + 2.0), as_recording(t, v, y - 1.0)]
    p = kp.fit(recs, Options(kp_levels=3, kp_linear="off", offset="per-file", u_range=[-1, 1]))
    np.testing.assert_allclose(p["offsets_per_file"], [2.0, -1.0], atol=1e-6)
    assert p["offset"] == pytest.approx(0.5, abs=1e-6)
    np.testing.assert_allclose(p["w"], w, atol=1e-6)


# --------------------------------------------------------------- preisach

def test_preisach_recovers_weights():
    t, v = rich_drive()
    n = 10
    g = play_outputs(v, np.arange(n) / n)
    alpha = np.linspace(0.5, 0.05, n)
    y = 0.7 * v ** 3 + 1.1 * v + g @ alpha + 0.25
    p = preisach.fit([as_recording(t, 10 * v, y)], Options(u_range=[-10, 10]))
    # gamma_1 (r = 0) is v itself: only p2 + alpha_1 is identifiable
    assert p["p2"] + p["alpha"][0] == pytest.approx(1.1 + alpha[0], abs=1e-6)
    np.testing.assert_allclose(p["alpha"][1:], alpha[1:], atol=1e-6)
    assert p["p1"] == pytest.approx(0.7, abs=1e-6)
    assert p["offset"] == pytest.approx(0.25, abs=1e-6)
    np.testing.assert_allclose(p["r_volts"], np.arange(n) / n * 10)
    assert nrmse(y, preisach.simulate(p, t, 10 * v)) < 1e-8


# ------------------------------------------------------------------- eupi

def test_eupi_recovers_tilts_weights_and_sets_kex():
    t, v = rich_drive()
    r_cpi = 0.9 * np.arange(1, 6) / 5
    r_upi = 0.9 * np.arange(1, 3) / 2
    true = eupiref.EUPIParams(a0=0.6, r_cpi=r_cpi, b=[0.3, 0.0, 0.2, 0.1, 0.05], r_upi=r_upi,
                              a_upi=[0.7, 1.5], d=[[0.1, 0.0], [0.05, 0.08]], p=[0.05, -0.02], p0=0.1)
    z = eupiref.eupi_model(v, true)
    y = 4.0 + 3.0 * z / np.max(np.abs(z))     # um, arbitrary scale and offset
    rec = as_recording(t, v, y)
    p = eupi.fit([rec], Options(eupi_n_cpi=5, eupi_n_upi=2, eupi_tilts=[0.5, 0.7, 1.2, 1.5],
                                eupi_n_tilts=2, eupi_poly=3, u_range=[-1, 1]))
    np.testing.assert_allclose(p["a_upi"], [0.7, 1.5])
    scale = p["y_half"] / (3.0 / np.max(np.abs(z)))   # fitted normalized units vs true ones
    assert p["a0"] * scale == pytest.approx(0.6, rel=1e-4)
    np.testing.assert_allclose(np.asarray(p["b"]) * scale, true.b, atol=1e-4)
    np.testing.assert_allclose(np.asarray(p["d"]) * scale, true.d, atol=1e-4)
    assert nrmse(y, eupi.simulate(p, t, v)) < 1e-6
    # the inverse's small-gain condition holds with the requested margin
    assert p["invertible"] is True
    ep = eupi.to_params(p)
    assert p["small_gain_margin"] == pytest.approx(eupiref.small_gain_margin(ep, -1, 1))
    # this model needs no k_ex for margin 0.05 ...
    assert p["margin_at_kex0"] > 0.05 and p["k_ex"] == 0.0
    # ... a larger required margin moves gain into G1 and is met exactly
    want = p["margin_at_kex0"] + 0.1
    q = eupi.fit([rec], Options(eupi_n_cpi=5, eupi_n_upi=2, eupi_tilts=[0.5, 0.7, 1.2, 1.5],
                                eupi_n_tilts=2, eupi_poly=3, u_range=[-1, 1], eupi_margin=want))
    assert q["invertible"] is True and q["k_ex"] > 0
    assert q["small_gain_margin"] == pytest.approx(want, abs=1e-9)
    assert eupiref.small_gain_margin(eupi.to_params(q), -1, 1) == pytest.approx(want, abs=1e-9)


# -------------------------------------------------------------------- rkp

def _rkp_truth(L=3, M=4, T=20000, dt=1e-3, seed=3):
    """Synthetic RKP data: drive with varying rate, true Theta, reference model output."""
    t = np.arange(T) * dt
    v = 0.9 * np.sin(2 * np.pi * (0.5 * t + 1.5 * t ** 2 / t[-1])) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.21 * t))
    grid = kpref.kp_grid(L)
    rate = kpref.rate_estimate(v, dt, 1.0, grid.nmin)
    centers, widths = rkp.rate_basis(float(np.percentile(np.abs(rate), 99.9)), M)
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.2, 1.0, (grid.N, M))
    y = kpref.rkp_model(v, grid, theta, dt, centers, widths)
    return t, v, y, grid, theta, centers, widths, rate


def test_rkp_batch_recovers_reference_model():
    t, v, y, grid, theta, centers, widths, _ = _rkp_truth()
    opts = Options(rkp_levels=3, rkp_neurons=4, rkp_rate_max=float(centers[-1]), rkp_rate_cutoff_hz=0,
                   rkp_smooth=0.0, rkp_ridge=0.0, rkp_linear="off", u_range=[-1, 1])
    p = rkp.fit([as_recording(t, v, y)], opts)
    np.testing.assert_allclose(p["centers"], centers)
    assert nrmse(y, rkp.simulate(p, t, v)) < 1e-6
    np.testing.assert_allclose(p["theta"], theta, atol=2e-3)


def pe_drive(T=8000, dt=1e-3, seed=5):
    """Triangles between random points at two speeds (4 and 12 FS/s): persistent excitation."""
    rng = np.random.default_rng(seed)
    v = np.empty(T)
    x, k = -1.0, 0
    while k < T:
        target = rng.uniform(-1, 1) if rng.uniform() < 0.7 else float(rng.choice([-1.0, 1.0]))
        speed = (4.0, 12.0)[rng.integers(2)]
        n = max(1, int(abs(target - x) / (speed * dt)))
        seg = np.linspace(x, target, n + 1)[1:]
        v[k:k + n] = seg[:T - k]
        k += n
        x = target
    return v


def test_rkp_online_gradient_converges_to_batch_solution():
    dt = 1e-3
    v = pe_drive()
    grid = kpref.kp_grid(2, s=0.5)
    rate = kpref.rate_estimate(v, dt, 1.0, grid.nmin)
    centers, widths = np.array([-12.0, 0.0, 12.0]), np.full(3, 5.0)
    psi = kpref.kp_outputs(v, grid)
    F = kpref.gaussian_rbf(rate, centers, widths)
    theta = np.random.default_rng(2).uniform(0.2, 1.0, (grid.N, 3))
    y = kpref.rkp_model(v, grid, theta, dt, centers, widths)
    A = (psi[:, :, None] * F[:, None, :]).reshape(len(v), -1)
    # persistent excitation: the regressor covariance is well away from singular
    assert np.linalg.eigvalsh(A.T @ A / len(v)).min() > 1e-3
    batch = np.linalg.lstsq(A, y, rcond=None)[0].reshape(grid.N, -1)
    np.testing.assert_allclose(batch, theta, atol=1e-9)
    # g larger than the paper's 0.8: its stage's units and time scale differ
    est, err, hist = rkp.online_gradient(psi, F, y, g=100.0, dt=dt, passes=10, record_every=len(v))
    dist = [np.linalg.norm(h - batch) / np.linalg.norm(batch) for h in hist]
    assert dist[0] > 0.1                       # far after one pass
    assert dist[-1] < 0.01                     # converged to the batch solution
    assert all(b < a for a, b in zip(dist, dist[1:]))   # shrinking pass after pass
    T = len(v)
    assert np.sqrt(np.mean(err[-T:] ** 2)) < 0.02 * np.sqrt(np.mean(err[:T] ** 2))


def test_rkp_smoothness_keeps_unexcited_rates_near_neighbours():
    # one frequency excites only a few Gaussians; with the penalty the others take
    # their neighbours' density instead of decaying towards 0, so a faster drive
    # (rates the data never had) is predicted better
    t = np.arange(10000) * 1e-3
    grid = kpref.kp_grid(3)
    v1 = 0.9 * np.sin(2 * np.pi * 1.0 * t)
    v2 = 0.9 * np.sin(2 * np.pi * 2.0 * t)
    y1 = kpref.kp_model(v1, grid, np.ones(grid.N))
    y2 = kpref.kp_model(v2, grid, np.ones(grid.N))
    base = Options(rkp_levels=3, rkp_neurons=7, rkp_rate_cutoff_hz=0, rkp_linear="off",
                   u_range=[-1, 1], rkp_rate_span=3.0, rkp_ridge=1e-6)
    smooth = rkp.fit([as_recording(t, v1, y1)], Options(base, rkp_smooth=1.0))
    loose = rkp.fit([as_recording(t, v1, y1)], Options(base, rkp_smooth=0.0))
    for p in (smooth, loose):
        assert nrmse(y1, rkp.simulate(p, t, v1)) < 0.003          # both fit the data (measured 0.0019)
    e_smooth = nrmse(y2, rkp.simulate(smooth, t, v2))            # measured 0.012
    e_loose = nrmse(y2, rkp.simulate(loose, t, v2))              # measured 0.026
    assert e_smooth < 0.015
    assert e_smooth < 0.6 * e_loose


# ------------------------------------------------------------------- CLI

@pytest.fixture
def synthetic_csv(tmp_path):
    t, v = rich_drive(T=4000)
    grid = kpref.kp_grid(4)
    y = kpref.kp_model(v, grid, np.linspace(0.1, 1.0, grid.N)) + 0.3 * v
    p = tmp_path / "fit.csv"
    save_recording(p, {"t": t, "u": 50 * v, "y": y}, meta={"sample_rate_hz": 1000})
    return p


@pytest.mark.parametrize("kind", ["kp", "rkp", "eupi", "preisach"])
def test_identify_simulate_round_trip(tmp_path, synthetic_csv, kind, capsys):
    model = tmp_path / f"{kind}.json"
    assert cli.main(["identify", "--model", kind, "--data", str(synthetic_csv), "--out", str(model)]) == 0
    m = load_model(model)
    assert m.kind == kind
    prov = m.provenance
    assert prov["data"][0]["path"] == str(synthetic_csv) and len(prov["data"][0]["sha256"]) == 64
    assert prov["data"][0]["rows"] == 4000
    assert prov["options"]["offset"] == "shared"
    assert any(k.startswith(kind + "_") for k in prov["options"])     # the kind's own options recorded
    assert not any(k.startswith(o + "_") for o in MODEL_KINDS if o != kind for k in prov["options"])
    out = tmp_path / "pred.csv"
    assert cli.main(["simulate", "--model", str(model), "--input", str(synthetic_csv), "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "t,y" and len(lines) == 4001
    pred = np.loadtxt(out, delimiter=",", skiprows=1)
    rec = load_recording(synthetic_csv)
    np.testing.assert_allclose(pred[:, 0], rec.t, rtol=1e-9, atol=1e-12)
    assert nrmse(rec.y, pred[:, 1]) == pytest.approx(prov["data"][0]["nrmse"], rel=1e-6, abs=1e-9)
    # KP-made data (L = 4; the default L = 10 grid and data-range normalization differ):
    # kp measured 0.005, the other kinds 0.005..0.06
    assert prov["data"][0]["nrmse"] < (0.01 if kind == "kp" else 0.1)


def test_identify_delay_is_kept_and_applied(tmp_path):
    t, v = rich_drive(T=4000)
    grid = kpref.kp_grid(4)
    d = 7
    vd = np.concatenate([np.full(d, v[0]), v[:-d]])
    y = kpref.kp_model(vd, grid, np.linspace(0.1, 1.0, grid.N))
    csv = tmp_path / "lag.csv"
    save_recording(csv, {"t": t, "u": v, "y": y})
    for delay, expect_small in ((0.0, False), (0.007, True)):
        model = tmp_path / "m.json"
        assert cli.main(["identify", "--model", "kp", "--data", str(csv), "--out", str(model),
                         "--delay-s", str(delay), "--kp-levels", "4", "--u-range", "-1", "1"]) == 0
        m = load_model(model)
        assert m.params["input_delay_s"] == delay
        assert (m.provenance["data"][0]["nrmse"] < 1e-6) == expect_small
    out = tmp_path / "p.csv"
    assert cli.main(["simulate", "--model", str(model), "--input", str(csv), "--out", str(out)]) == 0
    assert nrmse(y, np.loadtxt(out, delimiter=",", skiprows=1)[:, 1]) < 1e-6


def test_identify_bad_recording_exit_2_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("# sample_rate_hz: 10\nt,u,y\n0,0,0\n0.1,1,nan\n0.2,2,1\n")
    rc = cli.main(["identify", "--model", "kp", "--data", str(bad), "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(bad) in err and "line 4" in err and "'y'" in err
    assert not (tmp_path / "m.json").exists()


def test_simulate_refuses_bad_model_file(tmp_path, synthetic_csv, capsys):
    model = tmp_path / "m.json"
    assert cli.main(["identify", "--model", "preisach", "--data", str(synthetic_csv), "--out", str(model)]) == 0
    doc = json.loads(model.read_text())
    doc["version"] = 2
    model.write_text(json.dumps(doc))
    capsys.readouterr()
    rc = cli.main(["simulate", "--model", str(model), "--input", str(synthetic_csv), "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "newer" in err and err.count("\n") == 1
    doc["version"] = 1
    doc["params"]["alpha"] = [1.0, 2.0]         # n = 10 expects 10 weights
    model.write_text(json.dumps(doc))
    rc = cli.main(["simulate", "--model", str(model), "--input", str(synthetic_csv), "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "weights alpha" in err


def test_unavailable_kind_reported_not_crashing(tmp_path, synthetic_csv, capsys, monkeypatch):
    import piezoctl.ident as ident
    monkeypatch.setitem(ident.MODEL_KINDS, "hammerstein", "piezoctl.ident.does_not_exist")
    rc = cli.main(["identify", "--model", "hammerstein", "--data", str(synthetic_csv),
                   "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "not available" in err and "does_not_exist" in err
    # the other kinds still work in the same parser
    assert cli.main(["identify", "--model", "preisach", "--data", str(synthetic_csv),
                     "--out", str(tmp_path / "m.json")]) == 0


def test_bad_options_are_cli_errors(tmp_path, synthetic_csv, capsys):
    for extra, text in ((["--u-range", "5", "1"], "UMAX must be greater"),
                        (["--kp-levels", "0"], "--kp-levels 0"),
                        (["--skip-s", "1000"], "leaves fewer than 2 samples")):
        rc = cli.main(["identify", "--model", "kp", "--data", str(synthetic_csv),
                       "--out", str(tmp_path / "m.json"), *extra])
        err = capsys.readouterr().err
        assert rc == 2 and text in err, (extra, err)


# -------------------------------------------------------------- real data

@pytest.mark.skipif(not (REALDATA / "valve_20hz_forc.csv").exists(),
                    reason="../shared/realdata (real recordings) not present")
def test_real_valve_20hz_model_predicts_40hz():
    fit_rec = load_recording(REALDATA / "valve_20hz_forc.csv")
    test_rec = load_recording(REALDATA / "valve_40hz_forc.csv")
    p = kp.fit([fit_rec], Options())
    # measured 0.0137 (kp, L = 10, linear term; docs/identification.md)
    assert nrmse(test_rec.y, kp.simulate(p, test_rec.t, test_rec.u)) < 0.015
