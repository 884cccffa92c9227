"""cascade --cascade-joint: hysteresis, creep, mode and delay identified together, on known cascades.

The real-data figures (valve 20 Hz <-> 40 Hz) are covered by ``tools/bench-ident``
(docs/identification.md), not here: these tests use synthetic cascades whose
parameters are known.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.bench import ident_realdata as bench
from piezoctl.ident import cascade as C
from piezoctl.ident import cascade_joint as J
from piezoctl.ident import tf
from piezoctl.ident.common import IdentError, Options, nrmse
from piezoctl.io.recording import Recording, save_recording
from piezoctl.models import eupi as E

# thresholds and tilt on the eupi kind's grids (n_cpi 10: 0.09 i; n_upi 4: 0.225 i), so the
# truth is inside the model set
TRUE_H = E.EUPIParams(a0=0.55, r_cpi=np.array([0.18, 0.45, 0.72]), b=np.array([0.15, 0.1, 0.05]),
                      r_upi=np.array([0.45]), a_upi=np.array([0.7]), d=np.array([[0.05]]),
                      p=np.array([0.05, -0.03]), p0=0.0)
MODE_HZ, ZETA, DELAY_S = 300.0, 0.04, 0.5e-3     # 2.5 samples at 5 kHz
CREEP_TAU, CREEP_GAIN = 0.05, 1.5                # [s], [um per FS]
FS = 5000.0


def forc_drive(f_hz, periods=20, hold_s=0.2):
    """Rising triangles from -1 up to peaks growing to +1 (the valve's sweep), after a hold at -1."""
    t_hold = np.arange(int(hold_s * FS)) / FS
    v = [np.full(t_hold.size, -1.0)]
    n = int(round(FS / f_hz))
    for k, peak in enumerate(np.linspace(-0.8, 1.0, periods)):
        ph = np.arange(n) / n
        v.append(-1.0 + (peak + 1.0) * (1.0 - np.abs(2.0 * ph - 1.0)))
    v = np.concatenate(v)
    return np.arange(v.size) / FS, v


def true_output(t, v, v_before=0.0, settle_s=0.5):
    """The cascade, simulated independently of the fit's code: the drive held at v_before for
    settle_s before t = 0, EUPI, plus a creep lag, through the mode, delayed."""
    n0 = int(settle_s * FS)
    ve = np.concatenate([np.full(n0, v_before), v])
    te = np.arange(ve.size) / FS
    w = 50.0 + 40.0 * E.eupi_model(ve, TRUE_H) + CREEP_GAIN * tf.simulate_tf([1.0], [CREEP_TAU, 1.0], te, ve)
    wn = 2 * np.pi * MODE_HZ
    y = tf.simulate_tf([wn ** 2], [1.0, 2 * ZETA * wn, wn ** 2], te, w)
    y = np.interp(te - DELAY_S, te, y, left=y[0])
    return y[n0:]


def recording(f_hz, seed=0, noise=0.01):
    t, v = forc_drive(f_hz)
    y = true_output(t, v) + noise * np.random.default_rng(seed).standard_normal(t.size)
    return Recording(t=t, u=50.0 + 50.0 * v, y=y)


@pytest.fixture(scope="module")
def sweeps():
    return recording(20.0, seed=1), recording(40.0, seed=2)


@pytest.fixture(scope="module")
def fitted(sweeps):
    return C.fit([sweeps[0]], Options(cascade_joint=True, cascade_creep="2", cascade_u_before=50.0,
                                      u_range=[0.0, 100.0]))


def test_lti_columns_and_delay_match_the_reference_simulation():
    t = np.arange(2000) / FS
    x = np.sin(2 * np.pi * 30 * t) + 0.3 * np.sign(np.sin(2 * np.pi * 7 * t))
    num, den = J.mode_tf(400.0, 0.1)
    got = J.lti_columns(num, den, 1 / FS, np.column_stack([x, 2 * x]))
    np.testing.assert_allclose(got[:, 0], tf.simulate_tf(num, den, t, x), atol=1e-9)
    np.testing.assert_allclose(got[:, 1], 2 * got[:, 0], atol=1e-9)
    d = J.delay_columns(x[:, None], 2.5)[:, 0]
    np.testing.assert_allclose(d, np.interp(t - 2.5 / FS, t, x, left=x[0]), atol=1e-12)


def test_period_folds_deal_the_periods_round_robin():
    t, v = forc_drive(20.0)
    f = J.period_folds(t, v, 4)
    assert set(np.unique(f)) == {0, 1, 2, 3}
    n = int(FS / 20)
    k0 = int(0.2 * FS) + n // 2                       # inside a period: one fold throughout it
    blocks = [set(f[s:s + n // 4]) for s in range(k0, k0 + 8 * n, n)]
    assert all(len(b) == 1 for b in blocks)
    assert [b.pop() for b in blocks][:5] in ([0, 1, 2, 3, 0], [1, 2, 3, 0, 1], [2, 3, 0, 1, 2],
                                             [3, 0, 1, 2, 3])
    # fewer periods than folds: contiguous blocks
    assert list(np.unique(J.period_folds(t[:100], np.linspace(0, 1, 100), 4))) == [0, 1, 2, 3]


def test_joint_fit_recovers_mode_delay_creep_and_hysteresis(fitted):
    p = fitted
    assert p["method"] == "joint"
    assert p["mode_hz"] == pytest.approx(MODE_HZ, rel=0.002)
    assert p["zeta"] == pytest.approx(ZETA, rel=0.02)
    assert p["delay_s"] == pytest.approx(DELAY_S, abs=0.05 / FS)
    assert p["creep"]["tau_s"] == pytest.approx([0.01, 0.05])
    assert p["creep"]["gain_um"][1] == pytest.approx(CREEP_GAIN, rel=0.02)
    assert abs(p["creep"]["gain_um"][0]) < 0.02 * CREEP_GAIN
    h = p["hysteresis"]
    # EUPI weights in um per FS: y_half * a0 etc. against 40 * TRUE_H
    assert h["y_half"] * h["a0"] == pytest.approx(40 * TRUE_H.a0, rel=0.01)
    b = dict(zip(np.round(h["r_cpi"], 3), np.asarray(h["b"]) * h["y_half"]))
    for r, w in zip(TRUE_H.r_cpi, TRUE_H.b):
        assert b[round(r, 3)] == pytest.approx(40 * w, rel=0.02)


def test_identified_on_20hz_predicts_40hz(sweeps, fitted):
    test = sweeps[1]
    noise_floor = 0.01 / np.ptp(test.y)
    got = nrmse(test.y, C.simulate(fitted, test.t, test.u))
    assert got < 1.2 * noise_floor
    # the start-up step (drive from 50 V to 0 V at t = 0) is predicted, not only the sweep
    early = test.t < 0.02
    assert np.sqrt(np.mean((C.simulate(fitted, test.t, test.u)[early] - test.y[early]) ** 2)) < 0.05


def test_cross_validation_needs_the_creep_lag(sweeps):
    p = C.fit([sweeps[0]], Options(cascade_joint=True, cascade_u_before=50.0, u_range=[0.0, 100.0]))
    cv = dict(zip(p["cv"]["creep_counts"], p["cv"]["nrmse"]))
    assert p["cv"]["chosen"] >= 2                        # the truth's lag is the second one
    assert cv[2] < 0.5 * cv[0]
    assert p["cv"]["chosen"] == min(cv, key=cv.get)


def test_cli_round_trip_and_model_file(tmp_path, sweeps, capsys):
    paths = []
    for name, r in zip(("a20.csv", "a40.csv"), sweeps):
        save_recording(tmp_path / name, r)
        paths.append(str(tmp_path / name))
    out = tmp_path / "m.json"
    assert cli.main(["identify", "--model", "cascade", "--cascade-joint", "--cascade-creep", "2",
                     "--cascade-u-before", "50", "--u-range", "0", "100", "--data", paths[0],
                     "--out", str(out), "--quiet"]) == 0
    d = json.loads(out.read_text())["params"]
    assert d["method"] == "joint" and d["u_before"] == 50.0 and len(d["creep"]["gain_um"]) == 2
    capsys.readouterr()
    assert cli.main(["simulate", "--model", str(out), "--input", paths[1], "--out",
                     str(tmp_path / "p.csv"), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    direct = C.simulate(d, sweeps[1].t, sweeps[1].u)
    assert res["nrmse"] == pytest.approx(nrmse(sweeps[1].y, direct), rel=1e-6)


def test_bad_options_and_model_fields_are_refused(sweeps, fitted):
    with pytest.raises(IdentError, match="--cascade-order 2"):
        C.fit([sweeps[0]], Options(cascade_joint=True, cascade_order=3))
    with pytest.raises(IdentError, match="--cascade-cv-folds"):
        C.fit([sweeps[0]], Options(cascade_joint=True, cascade_cv_folds=1))
    with pytest.raises(IdentError, match="per-file"):
        C.fit([sweeps[0]], Options(cascade_joint=True, offset="per-file"))
    with pytest.raises(IdentError, match="--cascade-u-before: only with --cascade-joint"):
        C.fit([sweeps[0]], Options(cascade_u_before=0.0, cascade_fallback=True))
    t, u = sweeps[1].t, sweeps[1].u
    for bad in ({"creep": {"tau_s": [-0.1], "gain_um": [1.0]}}, {"creep": {"tau_s": [0.1], "gain_um": []}},
                {"delay_s": 5.0}, {"u_before": "x"}, {"den": [1.0, 2.0]}):
        with pytest.raises(IdentError):
            C.simulate({**fitted, **bad}, t, u)


def test_bench_covers_the_documented_figures():
    """docs/identification.md's cascade-joint row is what tools/bench-ident --kinds cascade-joint
    prints: the variant and every column's case exist in the bench."""
    doc = (Path(__file__).resolve().parents[2] / "docs" / "identification.md").read_text()
    assert "tools/bench-ident --kinds cascade-joint" in doc
    assert "cascade-joint" in bench.VARIANTS
    lines = doc.splitlines()
    top = [i for i, ln in enumerate(lines) if ln.startswith("| model |")][0]     # the real-data table
    end = next(i for i in range(top, len(lines)) if not lines[i].startswith("|"))
    cases = [c.strip() for c in lines[top].strip("|").split("|")[1:]]
    names = [c.name for c in bench.CASES]
    assert cases == names
    row = [ln for ln in lines[top:end] if ln.startswith("| cascade-joint |")]
    assert len(row) == 1 and len(row[0].strip("|").split("|")) == len(cases) + 1
    assert re.search(r"\| cascade-joint \| 0\.\d{4} \| 0\.\d{4} \|", row[0])
    opts = bench.options_for("cascade-joint", [], 0.0)
    assert opts["cascade_joint"] and opts["cascade_u_before"] == 0.0 and not opts.get("cascade_fallback")
    assert all(c.start_v == 0.0 for c in bench.CASES if c.name.startswith("valve"))


def test_residual_breakdown_parts_add_up_and_find_harmonic_error():
    t, v = forc_drive(20.0)
    y = true_output(t, v)
    f0 = 20.0
    sweep = t >= 0.2
    err = np.where(sweep, 0.05 * np.sin(2 * np.pi * 3 * f0 * t), 0.0)      # at the 3rd harmonic
    err[:50] += 0.3                                                        # start-up
    b = bench.residual_breakdown(t, 50 + 50 * v, y, y + err)
    parts = [b[k] for k in ("startup", "hold", "sweep_harmonics", "sweep_other")]
    assert sum(p ** 2 for p in parts) == pytest.approx(b["total"] ** 2, rel=1e-9)
    assert b["total"] == pytest.approx(nrmse(y, y + err), rel=1e-12)
    assert b["fundamental_hz"] == pytest.approx(f0, rel=0.02)
    assert b["sweep_harmonics"] > 20 * b["sweep_other"]
    assert b["startup"] == pytest.approx(np.sqrt(50 * 0.09 / t.size) / np.ptp(y), rel=1e-9)
    assert b["hold"] == 0.0
