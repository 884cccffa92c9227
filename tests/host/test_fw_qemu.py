"""The board image ``piezoctl-fw`` boots under QEMU and serves Modbus RTU.

QEMU 7.2's netduinoplus2 models no USB OTG core (its registers read 0) and
no flash interface: the image's USB init must give up within its bounded
waits and the RTU server on USART1 must answer, with the tick running from
RAM (link.ld's .ramfunc, the vector table's RAM copy) and the converter
drivers on QEMU's SPI (docs/target-cortex-m4.md). The PIL test
(test_calibrate_qemu.py) runs the PIL image; this one the image a board gets.
"""

import pathlib
import shutil
import time

import pytest

from piezoctl import device
from piezoctl.calibrate.target import QemuTarget

ROOT = pathlib.Path(__file__).resolve().parents[2]
IMAGE = ROOT / "build" / "cortex-m4" / "firmware" / "targets" / "cortex-m4" / "piezoctl-fw"


def test_board_image_boots_without_usb_and_serves_rtu():
    if shutil.which("qemu-system-arm") is None or not IMAGE.exists():
        pytest.skip("needs qemu-system-arm and the cortex-m4 build (piezoctl-fw)")
    with QemuTarget(image=str(IMAGE)) as q:
        ctl = device.connect(q.port, timeout=2.0)
        assert ctl.identity.tick_hz == 10000
        s1 = ctl.status()
        time.sleep(0.3)
        s2 = ctl.status()
        assert s2["tick_count"] > s1["tick_count"]  # the tick (from RAM) runs
