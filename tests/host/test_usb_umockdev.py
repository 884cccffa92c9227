"""The pyusb transport under umockdev: this machine has no USB, so a device
is described in tests/host/usb/piezoctl-1209-0001.umockdev (sysfs attributes
and descriptors of a vendor-class device with bulk endpoints 0x01/0x81,
VID:PID 1209:0001) and its bulk transfers are scripted in *.ioctl files
(umockdev's usbdevfs format, written by hand). umockdev-run's preload library
gives libusb that device and answers its URBs from the script; bulk OUT data
must match byte for byte, so these tests also check what the host sends.

Each case runs a small Python program inside umockdev-run and reads its JSON.
"""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess
import sys

import pytest

from piezoctl.transport import usb as usb_transport
from piezoctl.transport.pdu import read_request, write_request

HERE = pathlib.Path(__file__).resolve().parent / "usb"
DEVICE = HERE / "piezoctl-1209-0001.umockdev"
NODE = "/dev/bus/usb/001/002"

pytestmark = pytest.mark.skipif(shutil.which("umockdev-run") is None,
                                reason="umockdev-run is not installed (Debian package umockdev)")

PRELUDE = """
import json, sys
from piezoctl.transport import open_port, TransportError, ModbusExceptionError
def run(f):
    try:
        return {"ok": f()}
    except ModbusExceptionError as e:
        return {"error": type(e).__name__, "code": e.code, "msg": str(e)}
    except TransportError as e:
        return {"error": type(e).__name__, "msg": str(e)}
"""


def in_umockdev(body: str, ioctl: str | None = None) -> dict:
    cmd = ["umockdev-run", "--device", str(DEVICE)]
    if ioctl is not None:
        cmd += ["--ioctl", f"{NODE}={HERE / ioctl}"]
    cmd += ["--", sys.executable, "-c", PRELUDE + body]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def ioctl_lines(name: str) -> list[list[str]]:
    rows = []
    for line in (HERE / name).read_text().splitlines():
        if line.strip() and not line.startswith(("#", "@")):
            rows.append(line.split())
    return rows


def test_recorded_requests_are_what_the_host_frames():
    # The OUT transfers of the script are exactly our framing of the requests.
    outs = [bytes.fromhex(r[9]) for r in ioctl_lines("read-input.ioctl") if r[3] == "1"]
    assert outs == [usb_transport.frame(1, read_request(4, 0x0000, 2)),
                    usb_transport.frame(2, read_request(3, 0x0000, 1)),
                    usb_transport.frame(3, write_request(0x2000, [0x1234, 0xABCD]))]
    for r in ioctl_lines("read-input.ioctl") + ioctl_lines("stale-answer.ioctl"):
        data = bytes.fromhex(r[9])
        assert int(r[6]) == (len(data) if r[3] == "1" else 257)  # IN URBs: our read size
        assert int(r[7]) == len(data)
        usb_transport.unframe(data)  # every scripted transfer is a well-formed frame


def test_pyusb_enumerates_the_mocked_device():
    out = in_umockdev("""
import usb.core, usb.util
d = usb.core.find(idVendor=0x1209, idProduct=0x0001)
intf = d[0][(0, 0)]
print(json.dumps({"found": d is not None, "class": intf.bInterfaceClass,
    "eps": [(e.bEndpointAddress, usb.util.endpoint_type(e.bmAttributes), e.wMaxPacketSize) for e in intf]}))
""")
    assert out == {"found": True, "class": 0xFF, "eps": [[0x01, 2, 64], [0x81, 2, 64]]}


def test_bulk_exchanges_read_exception_write():
    out = in_umockdev("""
c = open_port("usb:1209:0001", timeout=0.5)
print(json.dumps([run(lambda: c.read_input(0, 2)), run(lambda: c.read_holding(0, 1)),
                  run(lambda: c.write_holding(0x2000, [0x1234, 0xABCD]))]))
""", "read-input.ioctl")
    assert out[0] == {"ok": [0x505A, 0x4003]}
    assert out[1]["error"] == "ModbusExceptionError" and out[1]["code"] == 2
    assert out[1]["msg"] == "usb:1209:0001: read holding 0x0000+1: illegal data address (exception 02)"
    assert out[2] == {"ok": None}


def test_request_not_in_the_script_is_refused():
    # umockdev fails a bulk OUT whose bytes are not recorded: the host must
    # send exactly the scripted request (here it asks 3 registers, not 2).
    out = in_umockdev("""
c = open_port("usb:1209:0001", timeout=0.5)
print(json.dumps(run(lambda: c.read_input(0, 3))))
""", "read-input.ioctl")
    assert out["error"] == "PortUnreachableError" and "USB error" in out["msg"]


def test_stale_answer_is_skipped():
    out = in_umockdev("""
c = open_port("usb:1209:0001", timeout=0.5)
print(json.dumps(run(lambda: c.read_input(0, 2))))
""", "stale-answer.ioctl")
    assert out == {"ok": [0x505A, 0x4003]}


def test_absent_product_is_unreachable():
    out = in_umockdev("""
print(json.dumps(run(lambda: open_port("usb:1209:0002", timeout=0.5))))
""")
    assert out == {"error": "PortUnreachableError", "msg": "usb:1209:0002: no USB device 1209:0002"}
