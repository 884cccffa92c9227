"""``piezoctl calibrate --target qemu``: processor in the loop, end to end.

The firmware image with the C stage model behind its converter seams
(``piezoctl-pil``) runs under ``qemu-system-arm -M netduinoplus2``; the host
calibrates it over Modbus RTU on QEMU's pseudo-terminal, the same pipeline as
``--target sil`` (docs/target-cortex-m4.md, "PIL"). One model kind (EUPI) to
keep it short. Its time (goal 5 minutes) is measured by
``tools/bench-calibrate --targets qemu``, not asserted here.
"""

import hashlib
import json
import pathlib
import shutil
import time

import pytest

from piezoctl import cli

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def pil_calibration(tmp_path_factory):
    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("needs qemu-system-arm and arm-none-eabi-gcc")
    out = tmp_path_factory.mktemp("pil")
    t0 = time.monotonic()
    rc = cli.main(["calibrate", "--target", "qemu", "--models", "eupi", "--out", str(out)])
    return rc, out, time.monotonic() - t0


def test_pil_summary_names_the_image_that_ran(pil_calibration):
    rc, out, _ = pil_calibration
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    t = s["target"]
    assert t["kind"] == "qemu" and t["transport"] == "rtu"
    image = pathlib.Path(t["image"])
    assert image.name == "piezoctl-pil" and image.read_bytes()[:4] == b"\x7fELF"
    assert t["image_sha256"] == hashlib.sha256(image.read_bytes()).hexdigest()
    assert not s["rolled_back"]


def test_pil_meets_the_tracking_goals(pil_calibration):
    rc, out, _ = pil_calibration
    s = json.loads((out / "summary.json").read_text())
    for key, goal in (("1", 10.0), ("10", 5.0), ("50", 3.0)):
        t = s["tracking"][key]
        assert t["rmse_uncompensated_um"] / t["rmse_compensated_um"] >= goal, (key, t)


def test_the_board_image_serves_its_register_map_over_rtu():
    """``piezoctl-fw`` itself (converters on SPI, tables in flash) under QEMU:
    identity and status over Modbus RTU. QEMU's SPI has no converter on it,
    so the ADC reads code 0, the rail: the sensor check faults, as on a board
    with no sensor."""
    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("needs qemu-system-arm and arm-none-eabi-gcc")
    from piezoctl.calibrate.target import QemuTarget, qemu_image
    from piezoctl.device import connect
    fw = qemu_image().parent / "piezoctl-fw"
    with QemuTarget(image=str(fw)) as q:
        ctl = connect(q.port, timeout=5.0)
        idn = ctl.identity
        assert (idn.n_axes, idn.tick_hz, idn.rec_capacity) == (1, 10000, 8192)
        assert (idn.scale.drive_min_v, idn.scale.drive_max_v) == (0.0, 150.0)
        st = ctl.status()
        assert st["tick_count"] > 0 and st["drive_q15"] == -32768  # safe drive: 0 V
        assert "sensor_implausible" in st["faults_names"]
        assert not st["armed"]
        # built without -DPIEZO_FW_UNLOCK_KEY: no key, every unlock refused (docs/target-cortex-m4.md)
        from piezoctl.device import DeviceError
        with pytest.raises(DeviceError, match="refused the unlock key"):
            ctl.unlock()
        assert ctl.status()["bad_unlocks"] == 1
