"""``piezoctl calibrate --target sil --stage two_axis.json``: both axes and the
cross-axis coupling (about 2.5 minutes).

The single-axis contract stays (tracking "1", "10", "50", model, table CRC;
no 100 Hz triangle on this 140 Hz stage); a two-axis controller adds axis 2's
calibration (DIR/axis2/) and ``coupling``: per receiving axis the RMS error
holding mid stroke while the other axis tracks a 10 and a 50 Hz triangle,
uncompensated, with the cross-coupling table applied, and with the held
axis' learned feedforward on top. Goals (issue 15): the held axis' error
reduced at least 10x (met by the part that repeats with the other axis'
period; the RMS is floored by the 2 nm sensor noise: docs/cross-coupling.md,
"Round 9"); the stage's own 50 Hz triangle at least 5x.
"""

import json
import struct
import time

from piezoctl import cli
from piezoctl.tables.image import parse_image
from piezoctl.sil.stage import default_stage_path
from sil_fixture import sil_binary

import pytest


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    sil_binary()  # skips when the SIL build is missing
    out = tmp_path_factory.mktemp("cal2")
    t0 = time.monotonic()
    rc = cli.main(["calibrate", "--target", "sil", "--stage", str(default_stage_path("two_axis")),
                   "--out", str(out)])
    return rc, out, time.monotonic() - t0


def test_two_axis_calibration_keeps_the_contract_and_adds_axis_2(calibration):
    rc, out, _ = calibration
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    for key in ("1", "10", "50"):
        assert set(s["tracking"][key]) >= {"rmse_uncompensated_um", "rmse_compensated_um"}
    assert "100" not in s["tracking"]      # 100 Hz is above 0.4 x the 140 Hz resonance
    img = (out / "table.bin").read_bytes()
    assert s["table_crc"] == struct.unpack_from("<I", img, len(img) - 4)[0]
    s2 = json.loads((out / "axis2" / "summary.json").read_text())
    assert s["axes"]["2"]["table_crc_hex"] == s2["table_crc_hex"]
    # the feedback design holds the 140 Hz stage: tracking improves at 1 and 10 Hz on both axes
    labels = {"learned": "+ learned feedforward", "ff_feedback": "+ dynamics (preview, shaper)",
              "hysteresis": "+ hysteresis inverse", "feedback": "feedback only (PI + notch)"}
    for summ in (s, s2):
        # a configuration that faulted the controller is never the one a figure comes from
        bad = {f["configuration"] for f in summ["acceptance_faults"]}
        for key, t in summ["tracking"].items():
            used = labels[t["compensation_used"]]
            name = f"{key} Hz triangle" if key != "multitone" else "multitone"
            assert used not in bad and f"{used}, {name}" not in bad, (key, t, bad)
            by_part = {"learned": "learned", "ff_feedback": "dynamics", "hysteresis": "hysteresis",
                       "feedback": "feedback"}[t["compensation_used"]]
            assert t["rmse_compensated_um"] == t["rmse_by_part_um"][by_part]
        assert summ["compensation"]["notch_hz"] == pytest.approx(140.0, abs=8.0)
        assert summ["tracking"]["1"]["reduction"] > 10.0
        assert summ["tracking"]["10"]["reduction"] > 2.0
    # its time (goal 420 s) is measured by tools/bench-calibrate --targets two-axis, not asserted here


def test_two_axis_stage_own_50hz_triangle(calibration):
    rc, out, _ = calibration
    for path in (out / "summary.json", out / "axis2" / "summary.json"):
        t = json.loads(path.read_text())["tracking"]["50"]
        # round 10: 3.77x in a loaded tools/test run, inferred: the learned run reported faulted after the host's
        # stop_wave cut the wave at a random phase and the figure taken from the dynamics inverse; the
        # triangles now end by themselves (docs/cross-coupling.md, "Round 10"): 13.9x-14.5x measured
        assert t["compensation_used"] == "learned", t
        assert t["reduction"] >= 5.0, t


def test_two_axis_coupling_is_reduced_and_reported(calibration):
    rc, out, _ = calibration
    s = json.loads((out / "summary.json").read_text())
    c = s["coupling"]
    assert set(c) == {"1", "2"}
    for axis, other in (("1", 2), ("2", 1)):
        e = c[axis]
        assert e["from_axis"] == other
        assert set(e) >= {"rmse_uncompensated_um", "rmse_compensated_um", "reduction"}
        # the other axis' 10 and 50 Hz triangles (60 % of its stroke), measured over 20 periods each:
        # valid figures, the learned correction never worse than the table alone, the stage's noise
        assert e["reduction"] == pytest.approx(e["rmse_uncompensated_um"] / e["rmse_compensated_um"])
        for f in ("10", "50"):
            b = e["by_frequency"][f]
            assert b["valid"] and b["periods"] == 20, b
            assert b["rmse_uncompensated_um"] > 0.004, b   # a coupling well above the 2 nm noise
            assert b["rmse_compensated_um"] <= b["rmse_table_only_um"], (axis, f, b)
            assert 0.0015 < b["noise_rms_um"] < 0.003, b
        tab = parse_image((out / e["table"]).read_bytes())
        assert f"{tab.crc:#010x}" == e["table_crc_hex"]
        assert tab.header["kind"] == 5  # cross_coupling
    html = (out / "report.html").read_text()
    assert "Cross-axis coupling" in html and c["1"]["table_crc_hex"] in html


def test_two_axis_coupling_left_after_learning(calibration):
    # the issue's 10x on the part of the error that repeats with the other axis' period (the coupling's;
    # noise-corrected): measured 24x-35x at 10 Hz and 49x-63x at 50 Hz in 4 calibrations (docs/cross-coupling.md,
    # "Round 9"; 16x and 22x at 10 Hz with trials of 0.5 s).
    # The RMS is floored by the 2 nm sensor noise: 7.9 nm at 10 Hz allows at most 3.8x; measured 2.0-2.3 nm
    # left at both frequencies (until round 9: at most 6 and 15 nm asserted, 2.4-3.9 and 7.3-10.6 measured)
    rc, out, _ = calibration
    c = json.loads((out / "summary.json").read_text())["coupling"]
    for axis in ("1", "2"):
        by_f = c[axis]["by_frequency"]
        for f in ("10", "50"):
            b = by_f[f]
            assert b["compensation_used"] == "learned", (axis, f, b)
            assert b["reduction_periodic"] >= 10.0, (axis, f, b)
            assert b["rmse_compensated_um"] <= 0.003, (axis, f, b)
