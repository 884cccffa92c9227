"""The pieces of tools/bench-upload: FC 23 read/write on every transport
(the table read-back and recorder readout use it), the RTU line pacing, and
the umockdev script generated from the firmware's answers."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import time

import pytest

from piezoctl import interface
from piezoctl.bench import upload as bench
from piezoctl.device import WINDOW, Controller
from piezoctl.fixtures.ctl import dcc_image
from piezoctl.transport import ModbusExceptionError, open_port
from piezoctl.transport.client import RegisterClient
from sil_fixture import ROOT, SilStage, sil  # noqa: F401  (fixture)

OFFSET = interface.HOLDING_REGISTERS["table_offset"][0]
TABLE_WINDOW = interface.HOLDING_REGISTERS["table_window"][0]


class TwoRequests(RegisterClient):
    """A transport without its own FC 23: the base class must write, then read."""

    def __init__(self):
        self.mem = [0] * 0x10000
        self.calls = []

    def _read(self, function, address, count):
        self.calls.append(("r", function, address, count))
        return self.mem[address:address + count]

    def _write(self, address, values):
        self.calls.append(("w", address, len(values)))
        self.mem[address:address + len(values)] = values


def test_read_write_falls_back_to_write_then_read():
    c = TwoRequests()
    assert c.read_write(0x2000, 3, 0x2001, [7, 8]) == [0, 7, 8]
    assert c.calls == [("w", 0x2001, 2), ("r", 3, 0x2000, 3)]
    with pytest.raises(ValueError):
        c.read_write(0x2000, 126, 0x2001, [1])
    with pytest.raises(ValueError):
        c.read_write(0x2000, 1, 0x2001, [0] * 122)
    with pytest.raises(ValueError):
        c.read_write(0x2000, 1, 0xFFFF, [1, 2])


def _staged_roundtrip(client, img: bytes) -> None:
    counter = bench.RequestCounter(client)
    ctl = Controller(client)
    ctl.upload_table(img)
    before = counter.snapshot()
    assert ctl.read_staged(len(img)) == img
    after = counter.snapshot()
    chunks = math.ceil(len(img) / (2 * WINDOW))
    assert {k: after[k] - before[k] for k in after} == {"FC3/4": 0, "FC16": 0, "FC23": chunks}
    # the offset is written before the window is read, in the same request
    words = client.read_write(TABLE_WINDOW, 2, OFFSET, [0, 10])
    assert bytes([words[0] & 0xFF, words[0] >> 8, words[1] & 0xFF, words[1] >> 8]) == img[10:14]
    assert client.read_holding(OFFSET, 2) == [0, 10]
    # a refused write (odd offset) answers an exception and reads nothing
    with pytest.raises(ModbusExceptionError) as info:
        client.read_write(TABLE_WINDOW, 2, OFFSET, [0, 11])
    assert info.value.code == 3
    assert client.read_holding(OFFSET, 2) == [0, 10]


def test_fc23_over_tcp_and_rtu(sil):  # noqa: F811
    img, _ = dcc_image()
    with open_port(sil.spec) as c:
        _staged_roundtrip(c, img)
    with open_port(f"rtu:{sil.pty}:115200:N") as c:
        _staged_roundtrip(c, img[::-1])


def test_paced_rtu_takes_at_least_the_line_time(tmp_path):
    baud = 9600  # the server's framer waits 3.5 characters at this rate too
    s = SilStage(tmp_path, "--rtu-baud", str(baud))
    try:
        client, paced = bench.open_paced_rtu(str(s.pty), baud)
        try:
            t0 = time.perf_counter()
            regs = client.read_input(0, 2)
            dt = time.perf_counter() - t0
        finally:
            client.close()
    finally:
        s.stop()
    assert regs[0] == 0x505A
    # request: unit, FC, start, count, CRC = 8; answer: unit, FC, byte count, 4, CRC = 9
    assert (paced.tx_chars, paced.rx_chars, paced.tx_frames) == (8, 9, 1)
    floor = (8 + 9 + 3.5) * 11 / baud  # characters both ways + the server's silence
    assert dt >= floor
    assert bench.rtu_line_ms(17, 1, baud) == pytest.approx(1e3 * (17 + 7) * 11 / baud)


@pytest.mark.skipif(shutil.which("umockdev-run") is None,
                    reason="umockdev-run is not installed (Debian package umockdev)")
def test_generated_usb_script_replays_upload_and_fc23(sil, tmp_path):  # noqa: F811
    img, _ = dcc_image()
    rec = bench.MbapRecorder(sil.port)
    ctl = Controller(rec)
    ctl.upload_table(img)
    assert ctl.read_staged(len(img)) == img
    rec.close()
    assert [p[0] for p, _ in rec.exchanges].count(23) == math.ceil(len(img) / (2 * WINDOW))
    script = tmp_path / "up.ioctl"
    script.write_text(bench.usb_script(rec.exchanges))
    prog = ("from piezoctl.transport import open_port\n"
            "from piezoctl.device import Controller\n"
            "from piezoctl.fixtures.ctl import dcc_image\n"
            "img, _ = dcc_image()\n"
            "c = Controller(open_port('usb:1209:0001', timeout=0.5))\n"
            "c.upload_table(img)\n"
            "print(c.read_staged(len(img)) == img)\n")
    proc = subprocess.run(["umockdev-run", "--device", str(bench.USB_DEVICE), "--ioctl",
                           f"{bench.USB_NODE}={script}", "--", sys.executable, "-c", prog],
                          capture_output=True, text=True, timeout=60,
                          env={"PYTHONPATH": str(ROOT / "host"), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "True"
