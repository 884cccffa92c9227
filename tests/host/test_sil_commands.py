"""The host commands of the tables issue against the virtual controller:
status, flash (good, refused, damaged), persistence across a restart, wave and
record, RTU on the pseudo-terminal, bad requests, clean shutdown."""

from __future__ import annotations

import json
import socket
import struct
import time

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.fixtures.ctl import dcc_image, eupi_image, refused_images
from piezoctl.io.recording import load_recording
from sil_fixture import SilStage, sil  # noqa: F401  (fixture)


def status(spec: str, capsys) -> dict:
    assert cli.main(["status", "--port", spec, "--json"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_status_json_has_identity_and_table_crc(sil, capsys):
    st = status(sil.spec, capsys)
    assert st["active_table_crc"] == 0
    assert st["tick_hz"] == 10000
    assert st["scale"]["drive_max_v"] == pytest.approx(150.0)
    t0 = st["tick_count"]
    time.sleep(0.2)
    assert status(sil.spec, capsys)["tick_count"] - t0 > 1000  # paced at 10 kHz


def test_flash_good_then_refused_keeps_the_active_table(sil, tmp_path, capsys):
    img, _ = dcc_image()
    (tmp_path / "t.bin").write_bytes(img)
    assert cli.main(["flash", "--port", sil.spec, "--quiet", str(tmp_path / "t.bin")]) == 0
    crc = struct.unpack_from("<I", img, len(img) - 4)[0]
    assert status(sil.spec, capsys)["active_table_crc"] == crc
    name, bad, reason = next(x for x in refused_images() if x[2] == "unstable_inverse")
    (tmp_path / "bad.bin").write_bytes(bad)
    assert cli.main(["flash", "--port", sil.spec, "--quiet", str(tmp_path / "bad.bin")]) == 4  # the controller refused
    assert "unstable_inverse" in capsys.readouterr().err
    assert status(sil.spec, capsys)["active_table_crc"] == crc
    # damaged files never reach the controller
    flipped = bytearray(img)
    flipped[40] ^= 4
    (tmp_path / "flip.bin").write_bytes(bytes(flipped))
    assert cli.main(["flash", "--port", sil.spec, "--quiet", str(tmp_path / "flip.bin")]) == 2
    assert "bad_crc" in capsys.readouterr().err
    assert status(sil.spec, capsys)["active_table_crc"] == crc


def test_table_survives_a_restart_and_rolls_back(tmp_path, capsys):
    s = SilStage(tmp_path)
    a, _ = dcc_image()
    b, _ = eupi_image()
    for n, img in (("a", a), ("b", b)):
        (tmp_path / f"{n}.bin").write_bytes(img)
        assert cli.main(["flash", "--port", s.spec, "--quiet", str(tmp_path / f"{n}.bin")]) == 0
    rc, out = s.stop()
    assert rc == 0 and "stopped after" in out
    s2 = SilStage(tmp_path, flash=s.flash)
    try:
        st = status(s2.spec, capsys)
        assert st["active_table_crc"] == struct.unpack_from("<I", b, len(b) - 4)[0]
        assert st["previous_table_crc"] == struct.unpack_from("<I", a, len(a) - 4)[0]
    finally:
        s2.stop()


def test_wave_and_record_open_loop(sil, tmp_path, capsys):
    out = tmp_path / "rec.csv"
    assert cli.main(["wave", "--port", sil.spec, "--kind", "triangle", "--volts", "--amplitude", "60",
                     "--offset", "75", "--freq", "5", "--cycles", "2", "--mode", "open_loop",
                     "--record", str(out), "--duration", "0.4"]) == 0
    rec = load_recording(out)
    assert len(rec.t) == 4000
    assert rec.u.max() == pytest.approx(135.0, abs=0.5) and rec.u.min() == pytest.approx(15.0, abs=0.5)
    # the stage follows its drive: displacement grows with voltage
    assert np.corrcoef(rec.u, rec.y)[0, 1] > 0.95
    assert np.ptp(rec.y) > 8.0  # micrometres


def test_rtu_on_the_pty_answers_like_tcp(sil, capsys):
    st_tcp = status(sil.spec, capsys)
    # parity N: this kernel refuses PARENB on a pseudo-terminal (EINVAL)
    st_rtu = status(f"rtu:{sil.pty}:115200:N", capsys)
    assert st_rtu["interface_crc"] == st_tcp["interface_crc"]
    assert st_rtu["tick_count"] > st_tcp["tick_count"]


def test_bad_requests_get_exceptions_and_the_controller_keeps_running(sil, capsys):
    with socket.create_connection(("127.0.0.1", sil.port), timeout=2) as s:
        # FC 0x2B (not supported) -> exception 01; then garbage that cannot be MBAP
        s.sendall(struct.pack(">HHHB", 1, 0, 2, 1) + bytes([0x2B]))
        rsp = s.recv(64)
        assert rsp[7] == 0x2B | 0x80 and rsp[8] == 0x01
        s.sendall(b"\xff" * 32)
    assert status(sil.spec, capsys)["armed"] == 0
    rc, out = sil.stop()
    assert rc == 0 and "overruns" in out
