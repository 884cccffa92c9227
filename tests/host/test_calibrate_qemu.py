"""``piezoctl calibrate --target qemu``: processor in the loop, end to end.

The firmware image with the C stage model behind its converter seams
(``piezoctl-pil``) runs under ``qemu-system-arm -M netduinoplus2``; the host
calibrates it over Modbus RTU on QEMU's pseudo-terminal, the same pipeline as
``--target sil`` (docs/target-cortex-m4.md, "PIL"). One model kind (EUPI) to
keep it short: about a minute here; the goal is 5 minutes for the whole
calibration.
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


def test_pil_meets_the_tracking_goals_in_time(pil_calibration):
    rc, out, seconds = pil_calibration
    s = json.loads((out / "summary.json").read_text())
    for key, goal in (("1", 10.0), ("10", 5.0), ("50", 3.0)):
        t = s["tracking"][key]
        assert t["rmse_uncompensated_um"] / t["rmse_compensated_um"] >= goal, (key, t)
    assert seconds < 300.0
