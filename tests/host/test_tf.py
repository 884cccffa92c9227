"""WCLS / PSO-WCLS transfer-function fits, FRF estimation, fit-tf CLI contract."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from piezoctl import cli
from piezoctl.ident import tf

TOP = Path(__file__).resolve().parents[2]

# The paper's 4th-order actuator model (fitted over 0.01-50 Hz).
B_PAPER = np.array([0.008933, -1.839, 260.4, 9.313e5, 3.096e7])
A_PAPER = np.array([1.0, 244.2, 3.605e4, 1.898e6, 3.343e7])
F_PAPER = np.logspace(-2, np.log10(50.0), 200)


def paper_h(f=F_PAPER):
    return tf.freqresp(B_PAPER, A_PAPER, 2 * np.pi * f)


def noisy(h, level, seed):
    rng = np.random.default_rng(seed)
    return h * (1 + level * (rng.standard_normal(h.size) + 1j * rng.standard_normal(h.size)) / np.sqrt(2))


def test_paper_poles_match_published_values():
    # The published poles are 100 x [-0.8456 +- 1.2107j, -0.3756 +- 0.1105j] (4 digits).
    p = tf.poles_of(A_PAPER) / 100
    want = np.array([-0.8456 - 1.2107j, -0.8456 + 1.2107j, -0.3756 - 0.1105j, -0.3756 + 0.1105j])
    assert np.allclose(np.sort_complex(p), np.sort_complex(want), atol=1.5e-3)


@pytest.mark.parametrize("method", ["wcls", "pso-wcls"])
def test_recovers_paper_model_from_its_frequency_response(method):
    frf = tf.FRF(F_PAPER, np.abs(paper_h()), np.rad2deg(np.unwrap(np.angle(paper_h()))))
    res = tf.fit_tf(frf, 4, method)
    assert res.den[0] == 1.0
    np.testing.assert_allclose(res.den, A_PAPER, rtol=1e-9)
    np.testing.assert_allclose(res.num, B_PAPER, rtol=1e-7)
    np.testing.assert_allclose(np.sort_complex(res.poles), np.sort_complex(tf.poles_of(A_PAPER)), rtol=1e-9)
    assert res.te < 1e-10
    assert res.stable


def test_wcls_solves_the_stated_normal_equations():
    h = noisy(paper_h(), 0.05, 3)
    w = 2 * np.pi * F_PAPER
    wt = np.linspace(0.5, 2.0, w.size) / np.abs(h) ** 2
    res = tf.wcls(w, h, 4, weights=wt)
    w0 = res.info["w0"]
    th_num = np.array([res.num[i] / w0 ** (4 - (4 - i)) for i in range(5)])
    th_den = np.array([res.den[i + 1] / w0 ** (i + 1) for i in range(4)])
    assert tf.wcls_normal_residual(w, h, 4, th_num, th_den, wt) < 1e-8
    # and a perturbed parameter vector does not
    assert tf.wcls_normal_residual(w, h, 4, th_num * 1.01, th_den, wt) > 1e-4


def test_lower_numerator_order_and_second_order_model():
    wn, z, k = 2 * np.pi * 80.0, 0.05, 1.3
    f = np.logspace(0, np.log10(300), 150)
    h = tf.freqresp([k * wn ** 2], [1, 2 * z * wn, wn ** 2], 2 * np.pi * f)
    res = tf.wcls(2 * np.pi * f, h, 2, n_num=0)
    np.testing.assert_allclose(res.den, [1, 2 * z * wn, wn ** 2], rtol=1e-9)
    np.testing.assert_allclose(res.num, [k * wn ** 2], rtol=1e-9)


def _unstable_wcls_case():
    """First noise seed for which plain WCLS returns an unstable pole (2 % noise)."""
    w = 2 * np.pi * F_PAPER
    for seed in range(60):
        h = noisy(paper_h(), 0.02, seed)
        if not tf.wcls(w, h, 4).stable:
            return w, h
    pytest.fail("no noisy data set made WCLS unstable")


def test_pso_wcls_returns_stable_better_model_when_wcls_is_unstable():
    w, h = _unstable_wcls_case()
    r0 = tf.wcls(w, h, 4)
    r1 = tf.pso_wcls(w, h, 4, seed=7)
    assert not r0.stable
    assert r1.stable and r1.info["flipped"] >= 1
    assert r1.te < r0.te
    # Te within a few noise levels of the truth's own error against the noisy data
    assert r1.te < 3 * tf.relative_error(paper_h(), h)
    # reproducible with the same seed
    r2 = tf.pso_wcls(w, h, 4, seed=7)
    np.testing.assert_array_equal(r1.den, r2.den)
    np.testing.assert_array_equal(r1.num, r2.num)


def test_pso_wcls_keeps_stable_wcls_unless_asked():
    # the paper's rule (refine=False): a stable WCLS result is the answer, the swarm does not run
    w = 2 * np.pi * F_PAPER
    h = noisy(paper_h(), 0.01, 1)
    r0 = tf.wcls(w, h, 4)
    assert r0.stable
    r1 = tf.pso_wcls(w, h, 4, refine=False)
    np.testing.assert_array_equal(r1.den, r0.den)
    assert r1.info["generations"] == 0 and r1.info["refined"] is False
    r2 = tf.pso_wcls(w, h, 4, always=True, refine=False)
    assert r2.stable and r2.te < r0.te and r2.info["generations"] >= 1
    # the default refines the same stable start
    r3 = tf.pso_wcls(w, h, 4)
    assert r3.info["generations"] == 0 and r3.info["refined"] is True
    assert r3.info["pso_te"] == r0.te and r3.te < r0.te


def te_true(res):
    """Te of a fit against the noise-free paper response (the issue's measure)."""
    return tf.relative_error(tf.freqresp(res.num, res.den, 2 * np.pi * F_PAPER), paper_h())


def test_refined_pso_wcls_is_within_te_001_of_the_true_response_one_seed():
    # Issue 15 item 5 on one seed (tools/bench-tf checks the median of 5): 2 % noise,
    # order 4. Measured: refined 0.0018; without the refinement (the paper's
    # PSO-WCLS, here equal to WCLS, which is stable for this seed) 0.037.
    w = 2 * np.pi * F_PAPER
    h = noisy(paper_h(), 0.02, 0)
    res = tf.pso_wcls(w, h, 4, seed=0)
    assert res.stable
    assert te_true(res) <= 0.005
    paper = tf.pso_wcls(w, h, 4, seed=0, refine=False)
    assert te_true(paper) > 0.01  # the margin above is not met without the refinement
    # the fit to the data is at the noise floor, not below it (no over-fitting):
    # the truth's own Te against these data is 0.0177
    assert 0.9 * tf.relative_error(paper_h(), h) < res.te < tf.relative_error(paper_h(), h)


def test_refinement_after_the_swarm_when_wcls_is_unstable():
    w, h = _unstable_wcls_case()
    res = tf.pso_wcls(w, h, 4, seed=7)
    assert res.stable and res.info["flipped"] >= 1 and res.info["generations"] >= 1
    assert res.te < res.info["pso_te"]
    assert te_true(res) <= 0.005


@pytest.mark.parametrize("level", [0.01, 0.02, 0.05])
def test_pso_wcls_is_always_stable_and_refinement_never_worsens_the_fit(level):
    w = 2 * np.pi * F_PAPER
    for seed in range(8):
        h = noisy(paper_h(), level, 100 + seed)
        start = tf.pso_wcls(w, h, 4, seed=seed, refine=False)
        res = tf.refine_output_error(w, h, start)
        assert res.stable and np.all(res.poles.real < 0)
        sq = lambda r: float(np.sum(np.abs(tf.freqresp(r.num, r.den, w) - h) ** 2 / np.abs(h) ** 2))  # noqa: E731
        assert sq(res) <= sq(start) * (1 + 1e-12)
        assert te_true(res) < te_true(start)


def test_refinement_recovers_odd_order_model_with_real_poles_from_a_poor_start():
    # 3rd order: a real pole at 5 Hz and a pair at 60 Hz, zeta 0.1; numerator order 1.
    # The start has every pole 30 % off (and real poles only): the sections must
    # turn a real pair into the complex one and keep the leftover real pole.
    p_true = np.array([-2 * np.pi * 5, 2 * np.pi * 60 * (-0.1 + 1j * np.sqrt(0.99)),
                       2 * np.pi * 60 * (-0.1 - 1j * np.sqrt(0.99))])
    den = np.real(np.poly(p_true))
    num = np.array([3.0, 3.0 * 2 * np.pi * 20]) * den[-1] / (3.0 * 2 * np.pi * 20)
    f = np.logspace(-1, np.log10(300), 150)
    w = 2 * np.pi * f
    h = tf.freqresp(num, den, w)
    start_den = np.real(np.poly(1.3 * np.array([-2 * np.pi * 5, -2 * np.pi * 40, -2 * np.pi * 90])))
    start = tf.TFResult(np.array([1.0, 1.0]), start_den, 1.0, "pso-wcls", {"w0": float(w.max())})
    res = tf.refine_output_error(w, h, start)
    np.testing.assert_allclose(res.den, den, rtol=1e-6)
    np.testing.assert_allclose(res.num, num, rtol=1e-6)
    assert res.te < 1e-7 and res.stable


def test_pso_stops_at_te_target():
    w, h = _unstable_wcls_case()
    loose = tf.pso_wcls(w, h, 4, te_target=10.0)  # the reflected-pole start already meets it
    assert loose.info["generations"] == 0 and loose.stable


def test_frf_from_time_recovers_a_known_system():
    fs = 10000.0
    t = np.arange(0, 4.0, 1 / fs)
    rng = np.random.default_rng(0)
    u = rng.standard_normal(t.size)
    num, den = [1.0, 40.0 * 2 * np.pi], [1.0, 2 * 0.3 * 2 * np.pi * 60, (2 * np.pi * 60) ** 2]
    num = np.array(num) * (2 * np.pi * 60) ** 2 / (40 * 2 * np.pi)
    y = tf.simulate_tf(num, den, t, u)
    frf = tf.frf_from_time(t, u, y, nperseg=4096, fmin=2.0, fmax=150.0, coherence_min=0.9)
    # ZOH sampling at 10 kHz adds a half-sample delay: compare against the discrete system
    ad, bd, cd, dd = tf.discretize(num, den, 1 / fs)
    bz, az = signal.ss2tf(ad, bd, cd, dd)
    _, hd = signal.freqz(bz[0], az, worN=frf.f_hz, fs=fs)
    assert frf.f_hz[0] >= 2.0 and frf.f_hz[-1] <= 150.0
    assert np.max(np.abs(frf.h - hd) / np.abs(hd)) < 0.03
    res = tf.wcls(frf.w, frf.h, 2, n_num=1)
    assert res.stable
    np.testing.assert_allclose(np.abs(res.poles), 2 * np.pi * 60, rtol=0.05)


def test_simulate_tf_starts_in_steady_state_and_matches_lsim():
    num, den = [2.0 * 100.0], [1.0, 100.0]
    t = np.arange(0, 0.2, 1e-4)
    u = 3.0 + np.sin(2 * np.pi * 5 * t)
    # lsim starts at zero state: compare after its transient has died out
    for method, interp in (("zoh", False), ("foh", True)):
        y = tf.simulate_tf(num, den, t, u, method=method)
        assert abs(y[0] - 6.0) < 1e-9
        _, yl, _ = signal.lsim((num, den), u, t, X0=None, interp=interp)
        np.testing.assert_allclose(y[1800:], yl[1800:], atol=1e-6)


def test_simulate_tf_foh_keeps_biproper_high_gain_models_accurate():
    # (1 + s/wz)^2 / (1 + s/wp)^2 with wp/wz ~ 58: high-frequency gain 3300
    wz, wp = 2 * np.pi * 22.6, 2 * np.pi * 1300
    num = np.polymul([1 / wz, 1], [1 / wz, 1]) * wp ** 2
    den = np.polymul([1 / wp, 1], [1 / wp, 1]) * wp ** 2
    t = np.arange(10000) / 5000.0
    u = np.sin(2 * np.pi * t)
    gain = abs(tf.freqresp(num, den, [2 * np.pi]))[0]
    y = tf.simulate_tf(num, den, t, u)
    assert abs(np.ptp(y[5000:]) / 2 - gain) < 1e-3 * gain
    y_zoh = tf.simulate_tf(num, den, t, u, method="zoh")
    assert np.ptp(y_zoh[5000:]) / 2 > 2 * gain  # every ZOH step excites the high-frequency gain


# --- CLI contract -----------------------------------------------------------------

def _write_frf(path, f, h, cols=("f_hz", "mag", "phase_deg")):
    data = {"f_hz": f, "mag": np.abs(h), "phase_deg": np.rad2deg(np.unwrap(np.angle(h)))}
    np.savetxt(path, np.column_stack([data[c] for c in cols]), delimiter=",",
               header=",".join(cols), comments="", fmt="%.17g")


def test_cli_fit_tf_writes_contract_json(tmp_path):
    frf = tmp_path / "frf.csv"
    out = tmp_path / "tf.json"
    _write_frf(frf, F_PAPER, paper_h(), cols=("phase_deg", "f_hz", "mag"))
    assert cli.main(["fit-tf", "--frf", str(frf), "--order", "4", "--method", "wcls", "--out", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["den"][0] == 1.0 and len(d["den"]) == 5 and len(d["num"]) == 5
    np.testing.assert_allclose(d["den"], A_PAPER, rtol=1e-9)
    p = np.array([complex(*z) for z in d["poles"]])
    np.testing.assert_allclose(np.sort_complex(p), np.sort_complex(tf.poles_of(A_PAPER)), rtol=1e-9)
    assert d["te"] < 1e-10


def test_cli_fit_tf_pso_via_tool_script(tmp_path):
    frf = tmp_path / "frf.csv"
    out = tmp_path / "tf.json"
    w, h = _unstable_wcls_case()
    _write_frf(frf, w / (2 * np.pi), h)
    r = subprocess.run([str(TOP / "tools" / "piezoctl"), "fit-tf", "--frf", str(frf), "--order", "4",
                        "--method", "pso-wcls", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert all(re < 0 for re, _ in d["poles"])
    assert d["stable"] is True


@pytest.mark.parametrize("content, message", [
    ("f_hz,mag\n1,2\n2,3\n", "missing column(s) phase_deg"),
    ("f_hz,mag,phase_deg\n1,2,0\n2,nan,0\n", "column mag is nan"),
    ("f_hz,mag,phase_deg\n1,2,0\n3,2,0\n2,2,0\n", "f_hz must increase strictly"),
    ("f_hz,mag,phase_deg\n1,2,0\n1,2,0\n", "f_hz must increase strictly"),
    ("f_hz,mag,phase_deg\n1,2,0\n2,x,0\n", "not a number"),
    ("", "empty file"),
])
def test_cli_fit_tf_bad_input_is_one_line_exit_2(tmp_path, capsys, content, message):
    frf = tmp_path / "frf.csv"
    frf.write_text(content)
    rc = cli.main(["fit-tf", "--frf", str(frf), "--order", "2", "--out", str(tmp_path / "o.json")])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err
    assert err.count("\n") == 1 and err.startswith("piezoctl fit-tf: error:")
    assert not (tmp_path / "o.json").exists()


def test_cli_fit_tf_missing_file_and_too_few_points(tmp_path, capsys):
    assert cli.main(["fit-tf", "--frf", str(tmp_path / "nope.csv"), "--order", "2", "--out", "x"]) == 2
    frf = tmp_path / "frf.csv"
    _write_frf(frf, F_PAPER[:3], paper_h(F_PAPER[:3]))
    assert cli.main(["fit-tf", "--frf", str(frf), "--order", "4", "--out", str(tmp_path / "o.json")]) == 2
    assert "cannot determine" in capsys.readouterr().err


def test_cli_no_refine_gives_the_papers_method_and_the_default_refines(tmp_path):
    frf = tmp_path / "frf.csv"
    _write_frf(frf, F_PAPER, noisy(paper_h(), 0.02, 0))
    outs = {}
    for name, extra in (("paper", ["--no-refine"]), ("refined", [])):
        out = tmp_path / f"{name}.json"
        assert cli.main(["fit-tf", "--frf", str(frf), "--order", "4", "--out", str(out), "--quiet"] + extra) == 0
        outs[name] = json.loads(out.read_text())
    paper, refined = outs["paper"], outs["refined"]
    assert paper["info"]["refined"] is False and refined["info"]["refined"] is True
    assert paper["te"] == paper["info"]["pso_te"] and refined["info"]["pso_te"] == paper["te"]
    assert paper["stable"] and refined["stable"]
    truth = lambda d: tf.relative_error(tf.freqresp(d["num"], d["den"], 2 * np.pi * F_PAPER), paper_h())  # noqa: E731
    assert truth(refined) <= 0.005 < 0.01 < truth(paper)


def test_cli_no_refine_with_wcls_is_refused(tmp_path, capsys):
    frf = tmp_path / "frf.csv"
    _write_frf(frf, F_PAPER, paper_h())
    out = tmp_path / "o.json"
    rc = cli.main(["fit-tf", "--frf", str(frf), "--order", "4", "--method", "wcls", "--no-refine", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "--no-refine applies to --method pso-wcls" in err
    assert not out.exists()


def test_cli_warns_about_a_real_pole_far_outside_the_data(tmp_path, capsys):
    # exact data of real poles at 10 Hz and 50 kHz seen over 1-50 Hz: WCLS recovers both; the
    # 50 kHz pole is a thousand times above the data and is said to be undetermined
    num, den = [2 * np.pi * 10 * 2 * np.pi * 5e4], np.polymul([1, 2 * np.pi * 10], [1, 2 * np.pi * 5e4])
    f = np.logspace(0, np.log10(50), 60)
    frf = tmp_path / "frf.csv"
    _write_frf(frf, f, tf.freqresp(num, den, 2 * np.pi * f))
    rc = cli.main(["fit-tf", "--frf", str(frf), "--order", "2", "--num-order", "0", "--method", "wcls",
                   "--out", str(tmp_path / "o.json"), "--json"])
    d = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert [round(r["f_hz"]) for r in d["poles_hz"]] == [10, 50000]
    (warn,) = [w for w in d["warnings"] if w.startswith("real pole at")]
    assert "5e+04 Hz is more than a decade outside the data (1-50 Hz)" in warn
