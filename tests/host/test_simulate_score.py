"""`piezoctl simulate` scores its output against y (nrmse, fit_percent, rmse_um, max_abs_um), plots, reads real time columns."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.io.recording import save_recording, write_csv

TOP = Path(__file__).resolve().parents[2]
STAGE = TOP / "firmware" / "targets" / "sil" / "stages" / "default.json"
REALDATA = next((p for p in (TOP.parent / "shared" / "realdata", TOP.parent.parent / "shared" / "realdata")
                 if p.is_dir()), TOP.parent / "shared" / "realdata")
PNG = b"\x89PNG\r\n\x1a\n"


def _run(capsys, *argv):
    rc = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _stage_lib_or_skip():
    from piezoctl.sil import stage
    try:
        stage.find_library()
    except Exception as exc:  # the C build has not run
        pytest.skip(f"stage library not built: {exc}")


def _hand_score(y, y_sim):
    """The definitions of docs/dynamics.md, written out in plain Python."""
    n = len(y)
    e = [a - b for a, b in zip(y, y_sim)]
    sse = sum(v * v for v in e)
    mean = sum(y) / n
    sst = sum((v - mean) ** 2 for v in y)
    rmse = math.sqrt(sse / n)
    return {"rmse_um": rmse, "max_abs_um": max(abs(v) for v in e),
            "nrmse": rmse / (max(y) - min(y)), "fit_percent": 100.0 * (1.0 - math.sqrt(sse) / math.sqrt(sst))}


def test_json_score_equals_a_hand_computation(tmp_path, capsys, monkeypatch):
    from piezoctl.commands import simulate
    y = [0.0, 1.5, 3.0, 2.0, -1.0, 0.5, 4.0, 2.5]
    u = [0.0, 1.0, 2.0, 1.0, -1.0, 0.0, 3.0, 2.0]
    t = [k * 1e-3 for k in range(len(y))]
    write_csv(tmp_path / "x.csv", {"t": t, "u": u, "y": y})
    # a stand-in for the stage: y_sim = 1.25 u + 0.1 (known, so the score can be computed by hand)
    monkeypatch.setattr(simulate, "STAGE_SIMULATOR", lambda p, tt, uu, u2: 1.25 * np.asarray(uu) + 0.1)
    rc, so, err = _run(capsys, "simulate", "--stage", "P.json", "--input", tmp_path / "x.csv",
                       "--out", tmp_path / "p.csv", "--json")
    assert rc == 0, err
    got = json.loads(so)
    want = _hand_score(y, [1.25 * v + 0.1 for v in u])
    for key in ("nrmse", "fit_percent", "rmse_um", "max_abs_um"):
        assert got[key] == pytest.approx(want[key], rel=1e-12), key
    assert got["samples"] == 8 and got["out"] == str(tmp_path / "p.csv")
    # the text says the same numbers
    rc, so, _ = _run(capsys, "simulate", "--stage", "P.json", "--input", tmp_path / "x.csv",
                     "--out", tmp_path / "p.csv")
    assert rc == 0 and f"nrmse {want['nrmse']:.4g}, fit {want['fit_percent']:.2f} %" in so


def test_no_y_no_score_and_constant_y_is_undefined(tmp_path, capsys, monkeypatch):
    from piezoctl.commands import simulate
    monkeypatch.setattr(simulate, "STAGE_SIMULATOR", lambda p, tt, uu, u2: np.asarray(uu) * 2.0)
    t = np.arange(50) * 1e-3
    write_csv(tmp_path / "drive.csv", {"t": t, "u": np.sin(t)})
    rc, so, err = _run(capsys, "simulate", "--stage", "P.json", "--input", tmp_path / "drive.csv",
                       "--out", tmp_path / "p.csv", "--json")
    assert rc == 0, err
    assert set(json.loads(so)) == {"out", "samples", "plot"}
    write_csv(tmp_path / "flat.csv", {"t": t, "u": np.sin(t), "y": np.full(t.size, 3.0)})
    rc, so, err = _run(capsys, "simulate", "--stage", "P.json", "--input", tmp_path / "flat.csv",
                       "--out", tmp_path / "p.csv", "--json")
    d = json.loads(so)
    assert rc == 0 and d["nrmse"] is None and d["fit_percent"] is None
    assert d["rmse_um"] == pytest.approx(math.sqrt(np.mean((3.0 - 2 * np.sin(t)) ** 2)))


def test_simulate_nrmse_is_the_one_identify_reports(tmp_path, capsys):
    # a user who identified a model and simulates it on the same file reads the same NRMSE
    t = np.arange(3000) / 1000.0
    v = np.sin(2 * np.pi * 1.0 * t) * (0.5 + 0.5 * np.sin(2 * np.pi * 0.2 * t))
    y = 2 * v + 0.3 * np.abs(v) * np.sign(np.gradient(v))
    rec = tmp_path / "rec.csv"
    save_recording(rec, {"t": t, "u": 50 * v, "y": y}, meta={"sample_rate_hz": 1000})
    model = tmp_path / "kp.json"
    rc, so, err = _run(capsys, "identify", "--model", "kp", "--data", rec, "--out", model)
    assert rc == 0, err
    reported = json.loads(model.read_text())["provenance"]["data"][0]["nrmse"]
    rc, so, err = _run(capsys, "simulate", "--model", model, "--input", rec, "--out", tmp_path / "p.csv", "--json")
    assert rc == 0, err
    assert json.loads(so)["nrmse"] == pytest.approx(reported, rel=1e-9)


def test_stage_reproduces_its_own_recording_and_plots(tmp_path, capsys):
    _stage_lib_or_skip()
    from piezoctl.sil.stage import simulate_stage
    t = np.arange(4000) / 1e4
    u = 75 + 40 * np.sin(2 * np.pi * 20 * t)
    y = simulate_stage(STAGE, t, u)  # seed 1, as simulate --stage
    write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y}, precision=15)
    png = tmp_path / "o.png"
    rc, so, err = _run(capsys, "simulate", "--stage", STAGE, "--input", tmp_path / "r.csv",
                       "--out", tmp_path / "p.csv", "--plot", png, "--json")
    assert rc == 0, err
    d = json.loads(so)
    assert d["max_abs_um"] < 1e-9 and d["fit_percent"] > 99.9999999
    assert png.read_bytes()[:8] == PNG


@pytest.mark.parametrize("name", ["actuator_150v_1hz.csv", "valve_20hz_forc.csv", "micromanipulator_1hz_model.csv"])
def test_stage_on_real_recordings_runs_on_their_printed_time_column(tmp_path, capsys, name):
    # issue 16: these ended in a traceback ("uniformly spaced"); their t is printed with a few digits
    _stage_lib_or_skip()
    src = REALDATA / name
    if not src.exists():
        pytest.skip("real recordings not present")
    rc, so, err = _run(capsys, "simulate", "--stage", STAGE, "--input", src, "--out", tmp_path / "p.csv", "--json")
    assert rc == 0, err
    d = json.loads(so)
    assert d["samples"] > 1000 and math.isfinite(d["rmse_um"]) and d["fit_percent"] is not None


def test_stage_refuses_a_time_column_with_a_break_in_one_line(tmp_path, capsys):
    _stage_lib_or_skip()
    t = np.arange(3000) / 1e4
    t[1500:] += 0.05  # a 50 ms pause
    write_csv(tmp_path / "x.csv", {"t": t, "u": np.full(t.size, 75.0)}, precision=15)
    out = tmp_path / "p.csv"
    rc, so, err = _run(capsys, "simulate", "--stage", STAGE, "--input", tmp_path / "x.csv", "--out", out)
    assert rc == 2 and err.count("\n") == 1 and not out.exists()
    assert "not uniformly sampled: from sample 1499 to 1500" in err and "the median step 0.0001 s" in err
