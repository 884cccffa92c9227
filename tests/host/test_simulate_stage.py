"""`piezoctl simulate --stage` runs the C stage model, sample for sample as `stage simulate`."""

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.io.recording import write_csv

stage = pytest.importorskip("piezoctl.sil.stage")


def _lib_or_skip():
    try:
        stage.find_library()
    except Exception as exc:  # the C build has not run
        pytest.skip(f"stage library not built: {exc}")


def test_simulate_with_stage_matches_stage_simulate(tmp_path):
    _lib_or_skip()
    import pathlib
    params = pathlib.Path(__file__).resolve().parents[2] / "firmware/targets/sil/stages/default.json"
    t = np.arange(5000) / 1e4
    u = 75 + 60 * np.sin(2 * np.pi * 5 * t)
    write_csv(tmp_path / "x.csv", {"t": t, "u": u, "y": np.zeros_like(t)})
    assert cli.main(["simulate", "--stage", str(params), "--input", str(tmp_path / "x.csv"),
                     "--out", str(tmp_path / "a.csv")]) == 0
    assert cli.main(["stage", "simulate", "--stage", str(params), "--input", str(tmp_path / "x.csv"),
                     "--out", str(tmp_path / "b.csv")]) == 0
    a = np.genfromtxt(tmp_path / "a.csv", delimiter=",", names=True)
    lines = [ln for ln in (tmp_path / "b.csv").read_text().splitlines() if not ln.startswith("#")]
    assert lines[0] == "t,y"
    b = {"y": np.array([float(ln.split(",")[1]) for ln in lines[1:]])}
    assert a.dtype.names == ("t", "y")
    # simulate writes 10 significant digits, stage simulate full precision
    assert np.allclose(a["y"], b["y"], rtol=1e-9, atol=0)
    assert np.ptp(a["y"]) > 5.0  # the stage moved by micrometres
