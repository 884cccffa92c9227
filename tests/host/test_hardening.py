"""Refusals of issue 13 (items 5-8) and issue 12 item 5 on the host: non-physical
recording values, malformed model files, simulate on a drive alone, the diagnose
wrapper's checks and atomic output, the CLI's last-resort guard, the connect error,
and sil_stage --flash on files that are not flash images."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
from pathlib import Path

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.io.modelfile import load_model, make_provenance, save_model
from piezoctl.io.recording import OUTLIER_K, RecordingError, load_recording, save_recording

from sil_fixture import sil_binary

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"


def _drive(T=4000, dt=1e-3):
    t = np.arange(T) * dt
    v = np.sin(2 * np.pi * 1.3 * t) * (0.6 + 0.4 * np.cos(2 * np.pi * 0.37 * t))
    return t, v


@pytest.fixture
def rec_csv(tmp_path):
    """A recording t,u,y,u2,x2 (4000 rows, 1 kHz): a hysteresis-like y and a small coupling."""
    t, v = _drive()
    u2 = 30 * np.sin(2 * np.pi * 0.7 * t)
    y = 2 * v + 0.3 * np.abs(v) * np.sign(np.gradient(v)) + 0.01 * u2
    p = tmp_path / "rec.csv"
    save_recording(p, {"t": t, "u": 50 * v, "y": y, "u2": u2, "x2": 0.1 * u2}, meta={"sample_rate_hz": 1000})
    return p


def _with_value(src: Path, dst: Path, row: int, col: str, value: str) -> int:
    """Copy src with one field replaced; return the 1-based line number of that row."""
    lines = src.read_text().splitlines()
    hdr = next(i for i, s in enumerate(lines) if not s.startswith("#"))
    j = lines[hdr].split(",").index(col)
    f = lines[hdr + 1 + row].split(",")
    f[j] = value
    lines[hdr + 1 + row] = ",".join(f)
    dst.write_text("\n".join(lines) + "\n")
    return hdr + 2 + row


def _run(capsys, *argv):
    rc = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


# ------------------------------------------------------------------ item 5: non-physical values

@pytest.mark.parametrize("col, value", [("y", "9.9e37"), ("y", "1e6"), ("y", "1e300"), ("u", "-1e9"), ("u2", "5e12")])
def test_non_physical_value_refused_naming_file_line_column(tmp_path, rec_csv, col, value):
    bad = tmp_path / "bad.csv"
    line = _with_value(rec_csv, bad, 1234, col, value)
    colno = rec_csv.read_text().splitlines()[1].split(",").index(col) + 1
    with pytest.raises(RecordingError) as info:
        load_recording(bad)
    msg = str(info.value)
    assert msg.startswith(f"{bad}: line {line}: column {colno} '{col}': non-physical value")
    assert "--drop-outliers" in msg and "\n" not in msg


def test_drop_outliers_drops_the_rows_and_says_where(tmp_path, rec_csv):
    bad = tmp_path / "bad.csv"
    line = _with_value(rec_csv, bad, 1234, "y", "1e6")
    rec = load_recording(bad, drop_outliers=True)
    assert len(rec) == 3999 and np.all(np.abs(rec.y) < 10)
    assert [(o.line, o.column, o.name, o.value) for o in rec.dropped] == [(line, 3, "y", 1e6)]
    assert load_recording(rec_csv, drop_outliers=True).dropped == []


def test_range_metadata_replaces_the_robust_rule(tmp_path):
    t = np.arange(100) * 1e-3
    u = np.zeros(100)
    u[50:55] = 150.0                                   # a short pulse from a held drive: legal
    p = tmp_path / "pulse.csv"
    save_recording(p, {"t": t, "u": u, "y": u / 10}, meta={"range_u": "0 150", "range_y": "-1 20"})
    assert len(load_recording(p)) == 100
    save_recording(p, {"t": t, "u": u, "y": u / 10}, meta={"range_u": "0 100"})
    with pytest.raises(RecordingError, match=r"line 53: column 2 'u': non-physical value 150, outside \[0, 100\] "
                                             r"\(range_u metadata\)"):
        load_recording(p)
    for bad in ("0", "5 1", "a b", "0 nan"):
        save_recording(p, {"t": t, "u": u, "y": u}, meta={"range_u": bad})
        with pytest.raises(RecordingError, match=r"line 1: metadata range_u"):
            load_recording(p)


def test_robust_rule_threshold_is_documented_value():
    assert OUTLIER_K == 100.0


@pytest.mark.skipif(not REALDATA.exists(), reason="../shared/realdata not present")
def test_no_real_recording_is_refused():
    files = sorted(REALDATA.glob("*.csv"))
    assert len(files) >= 9
    for f in files:
        rec = load_recording(f)
        assert rec.dropped == [] and len(rec) > 1000
    # the inverse-compensator runs end with a drive jump (-95 V -> -1.78 V): within range, kept
    r = load_recording(REALDATA / "valve_inverse_sine50.csv")
    assert r.u[-2] == pytest.approx(-95.052) and r.u[-1] == pytest.approx(-1.78)


def test_identify_refuses_an_outlier_and_writes_nothing(tmp_path, rec_csv, capsys):
    bad = tmp_path / "bad.csv"
    line = _with_value(rec_csv, bad, 2000, "y", "9.9e37")
    out = tmp_path / "m.json"
    rc, _, err = _run(capsys, "identify", "--model", "kp", "--data", bad, "--out", out)
    assert rc == 2 and err.count("\n") == 1
    assert f"{bad}: line {line}: column 3 'y'" in err
    assert not out.exists()
    rc, _, err = _run(capsys, "identify", "--model", "kp", "--data", bad, "--out", out, "--drop-outliers")
    assert rc == 0 and f"dropped 1 row(s) with non-physical values: line {line}, column 3 'y'" in err
    assert load_model(out).provenance["options"]["drop_outliers"] is True


def test_simulate_drop_outliers(tmp_path, rec_csv, capsys):
    model = tmp_path / "m.json"
    assert _run(capsys, "identify", "--model", "kp", "--data", rec_csv, "--out", model)[0] == 0
    bad = tmp_path / "bad.csv"
    line = _with_value(rec_csv, bad, 10, "u", "1e9")
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", model, "--input", bad, "--out", pred)
    assert rc == 2 and f"line {line}: column 2 'u'" in err and not pred.exists()
    rc, _, err = _run(capsys, "simulate", "--model", model, "--input", bad, "--out", pred, "--drop-outliers")
    assert rc == 0 and f"line {line}" in err
    assert len(pred.read_text().splitlines()) == 1 + 3999


# ------------------------------------------------------------------ item 8: loader details

@pytest.mark.parametrize("rate", ["0", "-5", "nan", "abc", "inf"])
def test_bad_sample_rate_refused_at_load(tmp_path, rec_csv, capsys, rate):
    p = tmp_path / "r.csv"
    p.write_text(rec_csv.read_text().replace("# sample_rate_hz: 1000", f"# sample_rate_hz: {rate}"))
    out = tmp_path / "m.json"
    rc, _, err = _run(capsys, "identify", "--model", "kp", "--data", p, "--out", out)
    assert rc == 2 and f"{p}: line 1: metadata sample_rate_hz '{rate}'" in err and not out.exists()


def test_utf8_bom_is_accepted(tmp_path, rec_csv):
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf" + rec_csv.read_bytes())
    a, b = load_recording(p), load_recording(rec_csv)
    assert a.meta == b.meta and np.array_equal(a.y, b.y)


def test_time_jump_refused(tmp_path):
    t = np.arange(100) * 1e-3
    t[-1] = 1e300
    p = tmp_path / "t.csv"
    save_recording(p, {"t": t, "u": np.zeros(100), "y": np.zeros(100)})
    with pytest.raises(RecordingError, match=r"line 101: column 1 't': time jumps"):
        load_recording(p)


# ------------------------------------------------------------------ issue 12 item 5: simulate on t,u

def _drive_only(tmp_path, with_u2=False):
    t, v = _drive()
    cols = {"t": t, "u": 50 * v}
    if with_u2:
        cols["u2"] = 30 * np.sin(2 * np.pi * 0.7 * t)
    p = tmp_path / ("drive_u2.csv" if with_u2 else "drive.csv")
    from piezoctl.io.recording import write_csv
    write_csv(p, cols)
    return p


@pytest.mark.parametrize("kind", ["kp", "rkp", "eupi", "preisach", "refined", "hammerstein"])
def test_simulate_runs_on_t_u_alone(tmp_path, rec_csv, capsys, kind):
    model = tmp_path / f"{kind}.json"
    assert _run(capsys, "identify", "--model", kind, "--data", rec_csv, "--out", model)[0] == 0
    drive = _drive_only(tmp_path, with_u2=kind == "hammerstein")
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", model, "--input", drive, "--out", pred)
    assert rc == 0, err
    got = np.loadtxt(pred, delimiter=",", skiprows=1)
    # the same model on the full recording gives the same prediction (y is not read)
    full = tmp_path / "full.csv"
    assert _run(capsys, "simulate", "--model", model, "--input", rec_csv, "--out", full)[0] == 0
    want = np.loadtxt(full, delimiter=",", skiprows=1)
    assert got.shape == (4000, 2) and np.all(np.isfinite(got))
    if kind != "hammerstein":        # hammerstein also reads x2, which the drive-only file lacks
        np.testing.assert_array_equal(got, want)


def test_simulate_cascade_on_t_u_alone(tmp_path, rec_csv, capsys):
    eupi = tmp_path / "eupi.json"
    assert _run(capsys, "identify", "--model", "eupi", "--data", rec_csv, "--out", eupi)[0] == 0
    m = load_model(eupi)
    params = {"hysteresis": m.params, "num": [1.0], "den": [0.002, 1.0], "c0": 0.0, "c1": 1.0}
    model = tmp_path / "cascade.json"
    save_model(model, "cascade", params, make_provenance([str(rec_csv)], {}))
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", model, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 0, err
    assert np.all(np.isfinite(np.loadtxt(pred, delimiter=",", skiprows=1)))


def test_simulate_hammerstein_without_u2_is_refused(tmp_path, rec_csv, capsys):
    model = tmp_path / "h.json"
    assert _run(capsys, "identify", "--model", "hammerstein", "--data", rec_csv, "--out", model)[0] == 0
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", model, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 2 and "needs a column u2" in err and not pred.exists()


# ------------------------------------------------------------------ item 6: model files

@pytest.fixture
def kp_model(tmp_path, rec_csv, capsys):
    model = tmp_path / "kp.json"
    assert _run(capsys, "identify", "--model", "kp", "--data", rec_csv, "--out", model)[0] == 0
    return model


def _mutated(model: Path, tmp_path: Path, mutate) -> Path:
    doc = json.loads(model.read_text())
    mutate(doc["params"])
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    return p


@pytest.mark.parametrize("mutate, message", [
    (lambda q: q.update(L=100000), r"params\.L: 100000 is outside \[1, 100\]"),
    (lambda q: q.update(L=100000, N=100000 * 100001 // 2), r"params\.L: 100000 is outside"),
    (lambda q: q["w"].__setitem__(3, None), r"params\.w\[3\]: is null, expected a number"),
    (lambda q: q.update(u_max=q["u_min"]), r"params\.u_min/u_max: empty drive range"),
    (lambda q: q.update(u_min=q["u_max"], u_max=q["u_min"]), r"params\.u_min/u_max: inverted drive range"),
    (lambda q: q.update(N=q["N"] + 1), r"params\.N: 56 operators, but L = 10 gives"),
    (lambda q: q["w"].append(1.0), r"params\.w: 56 weights w for a grid of 55 operators"),
    (lambda q: q.update(L="10"), r"params\.L: '10' is not an integer"),
    (lambda q: q.update(L=True), r"params\.L: True is not an integer"),
    (lambda q: q.update(offset="0.1"), r"params\.offset: '0\.1' is not a number"),
    (lambda q: q.update(offset=None), r"params\.offset: is null"),
    (lambda q: q.update(w={"a": 1}), r"params\.w: expected an array of numbers"),
    (lambda q: q.update(input_delay_s=-1.0), r"params\.input_delay_s: -1 is outside"),
    (lambda q: q.pop("w"), r"params\.w: missing"),
])
def test_simulate_refuses_bad_model_naming_field_and_writes_nothing(tmp_path, kp_model, capsys, mutate, message):
    bad = _mutated(kp_model, tmp_path, mutate)
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", bad, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith(f"piezoctl simulate: error: {bad}: ")
    assert re.search(message, err), err
    assert not pred.exists()


def test_deeply_nested_json_refused(tmp_path, capsys):
    p = tmp_path / "deep.json"
    p.write_text('{"format":"piezoctl-model","version":1,"kind":"kp","params":{"a":'
                 + "[" * 100000 + "]" * 100000 + "}}")
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", p, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 2 and f"{p}: JSON nested too deeply" in err and not pred.exists()


def test_nesting_limit_inside_params(tmp_path, kp_model):
    bad = _mutated(kp_model, tmp_path, lambda q: q.update(extra=json.loads("[" * 40 + "]" * 40)))
    with pytest.raises(Exception, match="nested deeper than 32 levels"):
        load_model(bad)


def test_rkp_preisach_eupi_shapes_checked(tmp_path, rec_csv, capsys):
    for kind, mutate, message in (
            ("rkp", lambda q: q["theta"][0].pop(), r"params\.theta\[0\]: \d+ values, expected"),
            ("rkp", lambda q: q.update(widths=[0.0] * len(q["widths"])), r"params\.widths: every width must be > 0"),
            ("preisach", lambda q: q.update(n=10 ** 6), r"params\.n: 1000000 is outside"),
            ("eupi", lambda q: q.update(y_half=0.0), r"params\.y_half: must not be 0"),
            ("eupi", lambda q: q["b"].append(1.0), r"params\.b: \d+ values, expected")):
        model = tmp_path / f"{kind}.json"
        if not model.exists():
            assert _run(capsys, "identify", "--model", kind, "--data", rec_csv, "--out", model)[0] == 0
        bad = _mutated(model, tmp_path, mutate)
        with pytest.raises(Exception, match=message):
            load_model(bad)


def test_simulate_refuses_non_finite_output(tmp_path, kp_model, capsys):
    bad = _mutated(kp_model, tmp_path, lambda q: q.update(w=[1e308] * len(q["w"])))
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", bad, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 2 and "non-finite output" in err and "nothing written" in err and not pred.exists()


def test_simulate_bounds_work_size_before_running(tmp_path, kp_model, capsys, monkeypatch):
    from piezoctl.commands import simulate
    monkeypatch.setattr(simulate, "MAX_WORK_VALUES", 1000)
    monkeypatch.setattr(simulate, "simulate_model", lambda *a, **k: pytest.fail("ran the model"))
    pred = tmp_path / "p.csv"
    rc, _, err = _run(capsys, "simulate", "--model", kp_model, "--input", _drive_only(tmp_path), "--out", pred)
    assert rc == 2 and "would hold 4000 samples x 56 values" in err and not pred.exists()


# ------------------------------------------------------------------ diagnose wrapper

def test_diagnose_refuses_before_running_and_leaves_no_folder(tmp_path, rec_csv, capsys, monkeypatch):
    import piezoctl.diagnose.run as run
    monkeypatch.setattr(run, "diagnose", lambda *a, **k: pytest.fail("diagnosis ran"))
    out = tmp_path / "out"
    two = tmp_path / "two.csv"
    two.write_text("t,u,y\n0,0,0\n1,1,1\n")
    rc, _, err = _run(capsys, "diagnose", "--calibration", rec_csv, "--recordings", two, "--out", out)
    assert rc == 2 and f"{two}: 2 samples" in err
    r5 = tmp_path / "r5.csv"
    r5.write_text(rec_csv.read_text().replace("sample_rate_hz: 1000", "sample_rate_hz: 500"))
    rc, _, err = _run(capsys, "diagnose", "--calibration", rec_csv, "--recordings", r5, "--out", out)
    assert rc == 2 and f"{r5}: sample rate 500 Hz differs from {rec_csv} (1000 Hz)" in err
    big = tmp_path / "big.csv"
    line = _with_value(rec_csv, big, 3000, "y", "1e300")
    rc, _, err = _run(capsys, "diagnose", "--calibration", big, "--recordings", rec_csv, "--out", out)
    assert rc == 2 and f"{big}: line {line}: column 3 'y'" in err
    assert sorted(os.listdir(tmp_path)) == sorted(["rec.csv", "two.csv", "r5.csv", "big.csv"])


def test_diagnose_failure_midway_leaves_no_partial_output(tmp_path, rec_csv, capsys, monkeypatch):
    import piezoctl.diagnose.run as run

    def half(cal, recs, out_dir, **kw):
        Path(out_dir, "base_model.json").write_text("{}")
        raise IndexError("index 0 is out of bounds")
    monkeypatch.setattr(run, "diagnose", half)
    out = tmp_path / "out"
    rc, _, err = _run(capsys, "diagnose", "--calibration", rec_csv, "--recordings", rec_csv, "--out", out)
    assert rc == 3 and err.count("\n") == 1 and "internal error: IndexError" in err and "PIEZOCTL_DEBUG" in err
    assert sorted(os.listdir(tmp_path)) == ["rec.csv"]
    # an existing output folder is left as it was
    out.mkdir()
    (out / "keep.txt").write_text("x")
    _run(capsys, "diagnose", "--calibration", rec_csv, "--recordings", rec_csv, "--out", out)
    assert os.listdir(out) == ["keep.txt"] and sorted(os.listdir(tmp_path)) == ["out", "rec.csv"]


def test_diagnose_success_publishes_the_folder(tmp_path, rec_csv, capsys, monkeypatch):
    import piezoctl.diagnose.run as run

    def ok(cal, recs, out_dir, **kw):
        Path(out_dir, "diagnosis.json").write_text("{}")
        return {"named": ["none"], "time_s": 0.0,
                "fit": {"base": {"nrmse": 0.1}, "refined": {"nrmse": 0.1},
                        "heldout": {"base_nrmse": 0.1, "refined_nrmse": 0.1}}}
    monkeypatch.setattr(run, "diagnose", ok)
    out = tmp_path / "out"
    assert _run(capsys, "diagnose", "--calibration", rec_csv, "--recordings", rec_csv, "--out", out)[0] == 0
    assert os.listdir(out) == ["diagnosis.json"] and sorted(os.listdir(tmp_path)) == ["out", "rec.csv"]


# ------------------------------------------------------------------ CLI guard, connect error

def test_unexpected_exception_is_one_line_exit_3(tmp_path, rec_csv, capsys, monkeypatch):
    from piezoctl.commands import simulate
    monkeypatch.setattr(simulate, "load_recording", lambda *a, **k: {}["boom"])
    rc, _, err = _run(capsys, "simulate", "--model", "m.json", "--input", rec_csv, "--out", tmp_path / "p.csv")
    assert rc == 3 and err.count("\n") == 1
    assert err.startswith("piezoctl simulate: internal error: KeyError: 'boom' at ")


def test_unreachable_port_says_cannot_connect_to_host_port(capsys):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    rc, _, err = _run(capsys, "status", "--port", f"tcp:127.0.0.1:{port}")
    assert rc == 5 and err.count("\n") == 1 and f"cannot connect to 127.0.0.1:{port}" in err


# ------------------------------------------------------------------ item 7: sil_stage --flash

FLASH_BYTES = 2 * (16 + 16384)


def _start(flash: Path):
    return subprocess.run([str(sil_binary()), "--modbus-tcp", "127.0.0.1:0", "--flash", str(flash)],
                          capture_output=True, text=True, timeout=10)


def _start_stop(flash: Path):
    p = subprocess.Popen([str(sil_binary()), "--modbus-tcp", "127.0.0.1:0", "--flash", str(flash)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = p.stdout.readline()
    p.terminate()
    p.communicate(timeout=10)
    return line


@pytest.mark.parametrize("size, what", [(10_000_000, "not a flash image: 10000000 bytes"),
                                        (FLASH_BYTES, f"not a flash image: {FLASH_BYTES} bytes as expected"),
                                        (100, "not a flash image: 100 bytes")])
def test_flash_refuses_a_foreign_file_and_leaves_it(tmp_path, size, what):
    f = tmp_path / "foreign.bin"
    data = bytes((i * 7 + 3) & 0xFF for i in range(size))
    f.write_bytes(data)
    r = _start(f)
    assert r.returncode == 1 and what in r.stderr and "left untouched" in r.stderr
    assert f.read_bytes() == data


def test_flash_reports_a_truncated_image(tmp_path):
    f = tmp_path / "sil.flash"
    assert "ready" in _start_stop(f)                  # created, erased
    assert f.stat().st_size == FLASH_BYTES
    assert "ready" in _start_stop(f)                  # a flash image of this layout is reused
    with open(f, "r+b") as fh:
        fh.truncate(20000)
    r = _start(f)
    assert r.returncode == 1 and f"truncated flash image: 20000 of {FLASH_BYTES} bytes" in r.stderr
    assert f.stat().st_size == 20000


def test_flash_empty_file_is_initialised(tmp_path):
    f = tmp_path / "empty.flash"
    f.write_bytes(b"")
    assert "ready" in _start_stop(f)
    assert f.read_bytes() == b"\xff" * FLASH_BYTES
