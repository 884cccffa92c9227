"""The interface definition, its generator and the generated Python view."""

import copy
import importlib.util
import pathlib
import subprocess
import sys
import tomllib

import pytest

from piezoctl import interface

ROOT = pathlib.Path(__file__).resolve().parents[2]


def load_generator():
    spec = importlib.util.spec_from_file_location("gen_interface", ROOT / "common" / "gen_interface.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def definition():
    with open(ROOT / "common" / "interface.toml", "rb") as fh:
        return tomllib.load(fh)


def test_generated_files_are_current():
    r = subprocess.run([sys.executable, str(ROOT / "common" / "gen_interface.py"), "--check"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_python_view_carries_version_and_crc_of_the_definition():
    gen = load_generator()
    d = definition()
    assert interface.LAYOUT_VERSION == d["meta"]["layout_version"]
    assert interface.INTERFACE_CRC32 == gen.canonical_crc(d)


def test_crc_changes_with_any_field():
    gen = load_generator()
    d = definition()
    d2 = copy.deepcopy(d)
    d2["modbus"]["holding"][0]["address"] += 1
    assert gen.canonical_crc(d2) != gen.canonical_crc(d)


def test_c_header_and_python_agree_on_the_crc():
    header = (ROOT / "firmware" / "generated" / "piezo_interface.h").read_text()
    assert f"#define PIEZO_INTERFACE_CRC32 0x{interface.INTERFACE_CRC32:08X}u" in header


def test_overlapping_registers_are_refused():
    gen = load_generator()
    regs = [{"name": "a", "address": 0x10, "type": "uint32"},
            {"name": "b", "address": 0x11, "type": "uint16"}]
    with pytest.raises(SystemExit, match="overlaps a"):
        gen.check_registers("input", regs)


def test_check_reports_stale_file(tmp_path, monkeypatch):
    gen = load_generator()
    for name in ("OUT_H", "OUT_C", "OUT_PY"):
        target = tmp_path / pathlib.Path(getattr(gen, name)).name
        target.write_text(pathlib.Path(getattr(gen, name)).read_text())
        monkeypatch.setattr(gen, name, target)
    monkeypatch.setattr(gen, "ROOT", tmp_path)
    assert gen.main(["--check"]) == 0
    gen.OUT_PY.write_text(gen.OUT_PY.read_text() + "# edited by hand\n")
    assert gen.main(["--check"]) == 1


def test_luts_follow_the_rounding_rule():
    import math
    assert interface.GAUSS_LUT_Q15[0] == 32767  # exp(0) = 1 clamps to the q15 maximum
    z = 7 * interface.GAUSS_ZMAX / (interface.GAUSS_LUT_N - 1)
    assert interface.GAUSS_LUT_Q15[7] == math.floor(math.exp(-z * z / 2) * 32768 + 0.5)
    assert interface.SINE_LUT_Q15[0] == interface.SINE_LUT_Q15[-1] == 0
    assert interface.SINE_LUT_Q15[256] == 32767
    assert interface.SINE_LUT_Q15[768] == -32768
