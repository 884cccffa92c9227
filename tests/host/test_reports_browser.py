"""Both reports in a headless browser: every image loads, and a screenshot is taken.

Debian's ``chromium`` (``tools/setup`` installs it) renders a copy of each
report with a script appended that counts the images whose ``naturalWidth`` is
0 once the page has loaded (an inline PNG that does not decode), and writes
the count into the DOM; ``--dump-dom`` prints the DOM and the test reads it.
A page with a corrupt image proves the check fails when it should. The
screenshots go to ``PIEZOCTL_REPORT_SHOTS`` (default: the test's temporary
directory) for a person to look at; the test asserts they are not blank.

Skipped, with the reason, when chromium is not installed, the SIL build is
missing (calibration) or the C stage library is not built (diagnosis).
"""

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CHECK = """<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !i.complete || i.naturalWidth === 0; }).length;
  var d = document.createElement('div');
  d.id = 'piezoctl-imgcheck';
  d.setAttribute('data-total', String(imgs.length));
  d.setAttribute('data-broken', String(bad));
  document.body.appendChild(d);
});
</script>"""


def _chromium() -> str:
    for name in ("chromium", "chromium-browser"):
        exe = shutil.which(name)
        if exe:
            return exe
    pytest.skip("chromium is not installed (tools/setup installs Debian's chromium)")


def _run_chromium(*args, timeout=120) -> subprocess.CompletedProcess:
    # --no-sandbox: the tests may run as root (containers); the pages are our own files
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
           "--no-first-run", "--disable-extensions", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def images_loaded(html_path: Path, work: Path) -> tuple[int, int]:
    """(images on the page, images that did not load) as chromium sees them."""
    page = html_path.read_text(encoding="utf-8")
    copy = work / f"check_{html_path.parent.name}_{html_path.name}"
    copy.write_text(page.replace("</body>", CHECK + "</body>"), encoding="utf-8")
    r = _run_chromium("--virtual-time-budget=20000", "--dump-dom", copy.as_uri())
    m = re.search(r'id="piezoctl-imgcheck"[^>]*data-total="(\d+)"[^>]*data-broken="(\d+)"', r.stdout)
    assert m, f"chromium did not run the check (rc {r.returncode}): {r.stderr[-500:]}"
    return int(m.group(1)), int(m.group(2))


def screenshot(html_path: Path, name: str, tmp: Path, height: int) -> Path:
    """A full-width screenshot of the page; asserts it is not blank."""
    from PIL import Image
    where = Path(os.environ.get("PIEZOCTL_REPORT_SHOTS", tmp))
    where.mkdir(parents=True, exist_ok=True)
    png = where / f"{name}.png"
    r = _run_chromium(f"--window-size=1200,{height}", f"--screenshot={png}", html_path.as_uri())
    assert png.exists(), r.stderr[-500:]
    im = np.asarray(Image.open(png).convert("L"))
    assert im.shape == (height, 1200)
    # a rendered report: text and plots, many grey levels, most of the page not white
    assert np.unique(im).size > 50
    assert np.mean(im < 250) > 0.05
    return png


def test_the_check_finds_a_broken_image(tmp_path):
    good = ("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8DwHwAFBQIAX8jx0gAAAABJRU5ErkJggg==")
    page = tmp_path / "page.html"
    page.write_text("<!doctype html><html><body>"
                    f"<img src='data:image/png;base64,{good}'>"
                    "<img src='data:image/png;base64,iVBORw0KGgoAAAA'>"
                    "</body></html>")
    assert images_loaded(page, tmp_path) == (2, 1)


@pytest.fixture(scope="module")
def calibration_report(tmp_path_factory):
    _chromium()
    from sil_fixture import sil_binary
    sil_binary()  # skips when the SIL build is missing
    out = tmp_path_factory.mktemp("cal")
    r = subprocess.run([str(ROOT / "tools" / "piezoctl"), "calibrate", "--target", "sil", "--out", str(out),
                        "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def diagnosis_report(tmp_path_factory):
    _chromium()
    try:
        from piezoctl.sil.stage import find_library
        find_library()
    except Exception as exc:  # noqa: BLE001 - library not built
        pytest.skip(f"libpiezo_stage.so not built ({exc})")
    from piezoctl.diagnose.cases import make_case
    from piezoctl.io.recording import load_recording, save_recording
    tmp = tmp_path_factory.mktemp("diag")
    case = make_case("delay", tmp / "case", scale=0.4, seed=3)
    # the valve's recorder reset: the last drive sample jumps back to the start
    rec = load_recording(case["recordings"][0])
    u = rec.u.copy()
    u[-1] = u[0] - 0.5 * np.ptp(u)
    jumped = tmp / "case" / "jumped.csv"
    save_recording(jumped, {"t": rec.t, "u": u, "y": rec.y})
    out = tmp / "out"
    r = subprocess.run([str(ROOT / "tools" / "piezoctl"), "diagnose", "--calibration", *case["calibration"],
                        "--recordings", str(jumped), *case["recordings"][1:], "--out", str(out), "--json",
                        "--max-terms", "1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out, jumped, u, json.loads(r.stdout), r.stderr


def test_calibration_report_images_load(calibration_report, tmp_path):
    html = calibration_report / "report.html"
    total, broken = images_loaded(html, tmp_path)
    assert broken == 0
    assert total == 5   # sweeps, frequency response, tracking, loops, error against frequency
    screenshot(html, "calibration_report", tmp_path, 7000)


def test_diagnosis_report_images_load(diagnosis_report, tmp_path):
    out = diagnosis_report[0]
    total, broken = images_loaded(out / "report.html", tmp_path)
    assert broken == 0
    assert total == 5   # residual time, spectrum, amplitude/rate, whiteness, overlay
    screenshot(out / "report.html", "diagnosis_report", tmp_path, 5000)


def test_diagnosis_flags_the_drive_jump(diagnosis_report):
    out, jumped, u, result, stderr = diagnosis_report
    doc = json.loads((out / "diagnosis.json").read_text())
    dd = [f for f in doc["drive_discontinuities"] if Path(f["file"]).name == "jumped.csv"]
    assert len(dd) == 1 and dd[0]["role"] == "recording"
    last = [j for j in dd[0]["jumps"] if j["where"] == "last sample"]
    assert len(last) == 1
    assert last[0]["sample"] == u.size - 1
    assert last[0]["u_after_v"] == pytest.approx(u[-1], abs=1e-3)
    assert last[0]["jump_v"] == pytest.approx(u[-1] - u[-2], abs=1e-3)
    # --json: one document on stdout carrying the same field; no progress on stderr
    assert [f["count"] for f in result["drive_discontinuities"] if f["file"] == str(jumped)] == [dd[0]["count"]]
    assert "piezoctl diagnose:" not in stderr
    page = (out / "report.html").read_text()
    assert "Discontinuities in the drive" in page and "last sample" in page
    assert "Whiteness" in page
    assert ("Where it acts" in page) == (doc["named"] != ["none"])
