"""``piezoctl calibrate --target sil``: the main job end to end (about 30 s).

The contract: DIR/summary.json with ``tracking`` keyed "1", "10", "50", each
with ``rmse_uncompensated_um`` and ``rmse_compensated_um``, the chosen model,
its held-out error and the table CRC; DIR/model.json and DIR/table.bin are
what was flashed; DIR/report.html exists. The goals on the default stage:
10x at 1 Hz, 5x at 10 Hz, 3x at 50 Hz, within 2 minutes.
"""

import json
import struct
import time

import pytest

from piezoctl import cli
from piezoctl.io.modelfile import load_model
from piezoctl.tables.image import parse_image
from sil_fixture import sil_binary


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    sil_binary()  # skips when the SIL build is missing
    out = tmp_path_factory.mktemp("cal")
    t0 = time.monotonic()
    rc = cli.main(["calibrate", "--target", "sil", "--out", str(out)])
    return rc, out, time.monotonic() - t0


def test_calibrate_writes_the_contract_files(calibration):
    rc, out, _ = calibration
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    for key in ("1", "10", "50"):
        assert set(s["tracking"][key]) >= {"rmse_uncompensated_um", "rmse_compensated_um"}
    assert s["model"] in ("eupi", "kp")
    assert 0 < s["heldout_nrmse"] < 0.05
    img = (out / "table.bin").read_bytes()
    assert s["table_crc"] == struct.unpack_from("<I", img, len(img) - 4)[0] == parse_image(img).crc
    assert load_model(out / "model.json").kind == s["model"]
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64") >= 3 and s["table_crc_hex"] in html
    assert not s["rolled_back"]
    assert s["target"] == {"kind": "sil", "transport": "tcp"}


def test_calibrate_meets_the_tracking_goals_in_time(calibration):
    rc, out, seconds = calibration
    s = json.loads((out / "summary.json").read_text())
    for key, goal in (("1", 10.0), ("10", 5.0), ("50", 3.0)):
        t = s["tracking"][key]
        assert t["rmse_uncompensated_um"] / t["rmse_compensated_um"] >= goal, (key, t)
    assert seconds < 120.0
