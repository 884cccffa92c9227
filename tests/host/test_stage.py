"""The host's binding of the C stage model (piezoctl.sil.stage).

The binding must give bit for bit the samples of the SIL path: the C program
build/sil/stage_sim drives the same library through stage_step() with DAC
codes, as the SIL firmware does, and writes the displacement of its ADC codes
with 17 significant digits (which reads back to the same double).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.sil import stage as sil_stage

REPO = Path(__file__).resolve().parents[2]
STAGE_SIM = REPO / "build" / "sil" / "stage_sim"

try:
    sil_stage.find_library()
    _missing = None
except sil_stage.StageLibraryError as exc:
    _missing = str(exc)

needs_lib = pytest.mark.skipif(_missing is not None, reason=f"C stage model not built: {_missing}")

needs_stage_sim = pytest.mark.skipif(
    _missing is not None or not STAGE_SIM.is_file(), reason=f"{STAGE_SIM} not built (cmake --build --preset sil)")


def _drive(n, fs=10000.0):
    t = np.arange(n) / fs
    u = 75.0 + 70.0 * np.sin(2 * np.pi * 7.0 * t) * np.cos(3.0 * t)
    u2 = 60.0 + 40.0 * np.sin(2 * np.pi * 23.0 * t)
    return t, u, u2


def _write_input(path, t, u, u2=None):
    with open(path, "w") as fh:
        fh.write("# drive for the stage model\n")
        fh.write("t,u,u2\n" if u2 is not None else "t,u\n")
        for k in range(t.size):
            row = [repr(float(t[k])), repr(float(u[k]))] + ([repr(float(u2[k]))] if u2 is not None else [])
            fh.write(",".join(row) + "\n")


def _read_csv(path):
    lines = [ln for ln in Path(path).read_text().splitlines() if ln and not ln.startswith("#")]
    names = lines[0].split(",")
    data = np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])
    return {n: data[:, j] for j, n in enumerate(names)}


def _bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


@needs_stage_sim
@pytest.mark.parametrize("name, seed", [("default", 1), ("default", 77), ("two_axis", 5)])
def test_binding_equals_the_sil_code_path_bit_for_bit(tmp_path, name, seed):
    params = sil_stage.default_stage_path(name)
    t, u, u2 = _drive(30000)
    two = name == "two_axis"
    _write_input(tmp_path / "in.csv", t, u, u2 if two else None)
    subprocess.run([str(STAGE_SIM), str(params), str(tmp_path / "in.csv"), str(tmp_path / "c.csv"), str(seed)],
                   check=True)
    c = _read_csv(tmp_path / "c.csv")
    out = sil_stage.simulate_stage(params, t, u, u2 if two else None, seed=seed)
    y = out[0] if two else out
    assert c["y"].size == t.size
    np.testing.assert_array_equal(_bits(y), _bits(c["y"]))
    if two:
        np.testing.assert_array_equal(_bits(out[1]), _bits(c["y2"]))
    # not a trivial output: the stage moved over most of its stroke
    assert np.ptp(y) > 10.0


@needs_lib
def test_same_seed_same_samples_other_seed_other_noise():
    params = sil_stage.default_stage_path()
    t, u, _ = _drive(5000)
    a = sil_stage.simulate_stage(params, t, u, seed=3)
    b = sil_stage.simulate_stage(params, t, u, seed=3)
    c = sil_stage.simulate_stage(params, t, u, seed=4)
    np.testing.assert_array_equal(_bits(a), _bits(b))
    assert np.mean(a != c) > 0.5
    assert np.max(np.abs(a - c)) < 0.05  # 2 nm rms noise: differences stay small


@needs_lib
def test_two_axis_returns_both_axes_and_u2_defaults_to_zero():
    params = sil_stage.default_stage_path("two_axis")
    t, u, _ = _drive(3000)
    y, y2 = sil_stage.simulate_stage(params, t, u, seed=1)
    y0, y20 = sil_stage.simulate_stage(params, t, u, np.zeros_like(u), seed=1)
    np.testing.assert_array_equal(_bits(y), _bits(y0))
    np.testing.assert_array_equal(_bits(y2), _bits(y20))
    with pytest.raises(ValueError, match="one-axis"):
        sil_stage.simulate_stage(sil_stage.default_stage_path(), t, u, u)


@needs_lib
def test_other_sample_rate_from_t():
    params = sil_stage.default_stage_path()
    t10, u10, _ = _drive(2000, fs=10000.0)
    t5, u5, _ = _drive(1000, fs=5000.0)
    a = sil_stage.simulate_stage(params, t10, u10, seed=2)
    b = sil_stage.simulate_stage(params, t5, u5, seed=2, sample_rate_hz=5000.0)
    c = sil_stage.simulate_stage(params, t5, u5, seed=2)
    np.testing.assert_array_equal(_bits(b), _bits(c))
    assert not np.array_equal(a[:1000], c)
    with pytest.raises(ValueError, match="uniformly"):
        sil_stage.simulate_stage(params, np.array([0.0, 0.1, 0.3]), np.zeros(3))


def _bad(tmp_path, text):
    p = tmp_path / "bad.json"
    p.write_text(text)
    return p


@needs_lib
def test_bad_parameter_files_give_clear_errors(tmp_path):
    t, u, _ = _drive(10)
    p = _bad(tmp_path, '{\n  "axes": [{\n    "hysteresis": {"alpah": 0.3}\n  }]\n}\n')
    with pytest.raises(sil_stage.StageParamsError, match=r"bad\.json:3: axes\[0\]\.hysteresis\.alpah: unknown key"):
        sil_stage.simulate_stage(p, t, u)
    p = _bad(tmp_path, '{"sample_rate_hz": 1.2.3}')
    with pytest.raises(sil_stage.StageParamsError, match=r"bad\.json:1: bad number"):
        sil_stage.simulate_stage(p, t, u)
    p = _bad(tmp_path, '{"axes": [{"adc": {"bits": 40}}]}')
    with pytest.raises(sil_stage.StageParamsError, match=r"axes\[0\]\.adc\.bits: 40, must be 1\.\.24"):
        sil_stage.simulate_stage(p, t, u)
    with pytest.raises(sil_stage.StageParamsError, match=r"missing\.json: cannot open"):
        sil_stage.simulate_stage(tmp_path / "missing.json", t, u)


def test_missing_library_tells_how_to_build(monkeypatch, tmp_path):
    monkeypatch.setenv(sil_stage.ENV_VAR, str(tmp_path / "libnothing.so"))
    with pytest.raises(sil_stage.StageLibraryError, match="PIEZOCTL_STAGE_LIB"):
        sil_stage.find_library()
    monkeypatch.delenv(sil_stage.ENV_VAR)
    monkeypatch.setattr(sil_stage, "REPO_ROOT", tmp_path)
    with pytest.raises(sil_stage.StageLibraryError, match=r"cmake --preset sil && cmake --build --preset sil"):
        sil_stage.find_library()


@needs_lib
def test_cli_stage_simulate(tmp_path, capsys):
    params = sil_stage.default_stage_path()
    t, u, _ = _drive(2000)
    _write_input(tmp_path / "in.csv", t, u)
    rc = cli.main(["stage", "simulate", "--stage", str(params), "--input", str(tmp_path / "in.csv"),
                   "--out", str(tmp_path / "out.csv"), "--seed", "9"])
    assert rc == 0
    out = _read_csv(tmp_path / "out.csv")
    assert list(out) == ["t", "y"]
    np.testing.assert_array_equal(_bits(out["y"]), _bits(sil_stage.simulate_stage(params, t, u, seed=9)))
    np.testing.assert_array_equal(out["t"], t)
    bad = _bad(tmp_path, '{"axes": [{"dac": {"bits": "16"}}]}')
    rc = cli.main(["stage", "simulate", "--stage", str(bad), "--input", str(tmp_path / "in.csv"),
                   "--out", str(tmp_path / "out2.csv")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "axes[0].dac.bits: must be a number, not a string" in err
    rc = cli.main(["stage", "simulate", "--input", str(tmp_path / "nothere.csv"), "--out", str(tmp_path / "o.csv")])
    assert rc == 2
