"""Operating the stage (issue 16 part 1) against the virtual controller:
servo on/off, move --wait, position --follow, params get/set/save/load and
their persistence in flash (A/B, CRC; a corrupt record ignored with its
reason), tables list/rollback, Controller.flash; and the enumerations, one
definition generated for C and Python (issue 16 part 8)."""

from __future__ import annotations

import json
import pathlib
import re

import pytest

from piezoctl import cli, device, interface
from piezoctl.device import connect
from piezoctl.errors import ControllerRefused
from piezoctl.fixtures.ctl import dcc_image, eupi_image
from sil_fixture import SilStage, sil  # noqa: F401  (fixture)

ROOT = pathlib.Path(__file__).resolve().parents[2]
# gains that close the default SIL stage's loop without a notch (kp >= 0.05 rings it)
GAINS = ["pid_kp=0.02", "pid_ki=0.002"]


def run(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def run_json(capsys, *argv) -> tuple[int, dict]:
    rc, out, err = run(capsys, *argv, "--json")
    return rc, json.loads(out) if out.strip() else {"stderr": err}


# ---------------------------------------------------------------- enumerations
def test_enumerations_are_one_definition_for_c_and_python():
    header = (ROOT / "firmware" / "generated" / "piezo_interface.h").read_text()
    for name, values in interface.ENUMS.items():
        m = re.search(r"enum piezo_enum_%s \{(.*?)\};" % name, header, re.S)
        assert m, name
        prefix = re.search(r"(\w+)_N = ", m.group(1)).group(1)
        c_values = {k: int(v) for k, v in re.findall(prefix + r"_([A-Z0-9_]+) = (\d+),", m.group(1))}
        assert c_values == {k.upper(): v for k, v in values.items()}, name
    # the host takes them from the generated module, not from a copy
    assert device.MODES is interface.ENUMS["mode"]
    assert device.SIGNALS is interface.ENUMS["rec_signals"]
    assert device.WAVE_KINDS is interface.ENUMS["wave_kind"]
    assert device.TABLE_COMMANDS is interface.ENUMS["table_command"]
    for reg, enum in interface.REGISTER_ENUMS.items():
        assert enum in interface.ENUMS, reg
    # the command switches of regmap.c name the generated constants, not numbers
    regmap = (ROOT / "firmware" / "control" / "regmap.c").read_text()
    for reg in ("COMMAND", "TABLE_COMMAND", "PARAMS_COMMAND", "MODE", "WAVE_KIND", "REC_TRIGGER", "REF_SOURCE"):
        m = re.search(r"case PIEZO_HREG_%s:(.*?)(?=case PIEZO_HREG_)" % reg, regmap.split("static int legal")[1], re.S)
        assert m and not re.search(r"\bv [<>=]=? \d", m.group(1)), reg
    assert not re.search(r"case \d+: \(void\)piezo_ctl_", regmap)


# ---------------------------------------------------------------- servo, move, position
def test_servo_refused_without_gains_and_move_refused_with_servo_off(sil, capsys):
    rc, _out, err = run(capsys, "servo", "on", "--port", sil.spec)
    assert rc == 2 and "PID gains are 0" in err
    assert connect(sil.spec).status()["armed"] == 0           # nothing changed
    rc, _out, err = run(capsys, "move", "--port", sil.spec, "--position", "10")
    assert rc == 2 and "disarmed" in err
    rc, res = run_json(capsys, "servo", "off", "--port", sil.spec)
    assert rc == 0 and not res["armed"] and "off already" in res["note"]


def test_servo_on_move_wait_position_follow_servo_off(sil, capsys):
    assert run(capsys, "params", "set", "--port", sil.spec, *GAINS)[0] == 0
    rc, res = run_json(capsys, "servo", "on", "--port", sil.spec)
    assert rc == 0 and res["mode"] == "feedback" and res["armed"]
    rc, res = run_json(capsys, "move", "--port", sil.spec, "--position", "12", "--wait", "--tolerance", "0.05")
    assert rc == 0, res
    assert res["settled"] and abs(res["error_um"]) <= 0.05 and abs(res["position_um"] - 12) <= 0.05
    assert 0 < res["time_s"] < 2
    # a position outside the stage's range: refused, nothing changed
    rc, _out, err = run(capsys, "move", "--port", sil.spec, "--position", "1e3")
    assert rc == 2 and "outside the stage's range" in err
    rc, out, _err = run(capsys, "position", "--port", sil.spec, "--follow", "--interval", "0.02", "--count", "3",
                        "--json")
    lines = [json.loads(x) for x in out.splitlines()]
    assert rc == 0 and len(lines) == 3
    assert all(abs(r["position_um"] - 12) < 0.1 and r["mode"] == "feedback" for r in lines)
    # servo off: the drive of the moment is held, open loop (the jump-free
    # switch itself is checked tick by tick in tests/firmware/params_store.c)
    ctl = connect(sil.spec)
    rc, res = run_json(capsys, "servo", "off", "--port", sil.spec)
    assert rc == 0 and res["mode"] == "direct" and res["armed"]
    held = {ctl.status()["drive_q15"] for _ in range(20)}
    assert len(held) == 1                                         # constant while the position drifts
    setpoint = ctl.client.read_holding(interface.HOLDING_REGISTERS["setpoint_q15"][0], 1)[0]
    assert setpoint == held.pop() & 0xFFFF
    rc, _out, err = run(capsys, "move", "--port", sil.spec, "--position", "11")
    assert rc == 2 and "servo is off" in err
    # servo on again from the held drive: closed loop at the present position
    rc, res = run_json(capsys, "servo", "on", "--port", sil.spec)
    assert rc == 0 and res["mode"] == "feedback"


def test_move_wait_that_does_not_settle_exits_1(sil, capsys):
    run(capsys, "params", "set", "--port", sil.spec, *GAINS)
    run(capsys, "servo", "on", "--port", sil.spec)
    rc, res = run_json(capsys, "move", "--port", sil.spec, "--position", "15", "--wait", "--tolerance", "1e-6",
                       "--timeout", "0.3")
    assert rc == 1 and res["settled"] is False and res["target_um"] == 15


# ---------------------------------------------------------------- parameters
def test_params_set_save_survive_a_restart(tmp_path, capsys):
    s = SilStage(tmp_path)
    try:
        rc, res = run_json(capsys, "params", "get", "--port", s.spec)
        assert rc == 0 and res["state"]["source"] == "defaults" and res["state"]["seq"] == 0
        assert res["params"]["pid_kp"]["unit"] == "1" and res["params"]["limit_max"]["unit"] == "V"
        fir = [0.5, -0.25] + [0.0] * 29 + [0.75]   # the dynamics inverse's 32 taps (q13)
        rc, res = run_json(capsys, "params", "set", "--port", s.spec, "pid_kp=0.25", "limit_max_step=0.5",
                           "shaper=0.25,0.5,0.25", "shaper_ticks=4", "dyninv_taps=32", "dyninv_ticks=3",
                           "dyninv=" + ",".join(map(str, fir)))
        assert rc == 0 and res["state"]["source"] == "changed"
        assert res["params"]["pid_kp"]["raw"] == 1 << 22
        assert res["params"]["shaper"]["raw"] == [8192, 16384, 8192]
        assert res["params"]["dyninv"]["raw"] == [4096, -2048] + [0] * 29 + [6144]
        step = res["params"]["limit_max_step"]
        assert abs(step["value"] - 0.5) <= 150.0 / 65536 and step["raw"] == round(0.5 / (150.0 / 65536))
        rc, res = run_json(capsys, "params", "save", "--port", s.spec)
        assert rc == 0 and res["state"] == {"source": "flash", "seq": 1, "result": "ok", "ignored": "ok",
                                            "wave": "saved"}
        run(capsys, "params", "set", "--port", s.spec, "pid_kp=0.5")
        assert run_json(capsys, "params", "save", "--port", s.spec)[1]["state"]["seq"] == 2
    finally:
        s.stop()
    s = SilStage(tmp_path, flash=s.flash)
    try:
        rc, res = run_json(capsys, "params", "get", "--port", s.spec)
        assert res["state"]["source"] == "flash" and res["state"]["seq"] == 2
        assert res["params"]["pid_kp"]["value"] == 0.5 and res["params"]["shaper_ticks"]["value"] == 4
        assert res["params"]["dyninv_taps"]["value"] == 32 and res["params"]["dyninv_ticks"]["value"] == 3
        assert res["params"]["dyninv"]["value"] == fir     # the FIR's taps survive a restart
        # load and defaults
        run(capsys, "params", "set", "--port", s.spec, "pid_kp=0.125")
        assert run_json(capsys, "params", "defaults", "--port", s.spec)[0] == 0
        assert run_json(capsys, "params", "get", "--port", s.spec, "pid_kp")[1]["params"]["pid_kp"]["value"] == 0
        assert run_json(capsys, "params", "load", "--port", s.spec)[0] == 0
        assert run_json(capsys, "params", "get", "--port", s.spec, "pid_kp")[1]["params"]["pid_kp"]["value"] == 0.5
    finally:
        s.stop()


def test_wave_and_learned_feedforward_survive_a_restart(tmp_path, capsys):
    """params save keeps the wave and the learned feedforward played with it;
    after a restart they are loaded, not started; wave --saved plays them."""
    import numpy as np
    from piezoctl.calibrate import ilc
    s = SilStage(tmp_path)
    try:
        ctl = connect(s.spec)
        ctl.unlock()
        ctl.configure_wave("triangle", offset_q15=0, amplitude_q15=8000, f_hz=10.0)
        c_um = 0.01 * np.sin(2 * np.pi * np.arange(200) / 200)        # one period's correction
        up = ilc.upload(ctl, c_um, 10.0)
        assert ctl.status()["wave_ff_n_live"] == up["n"] == 200
        staged = ctl.client.read_holding(interface.HOLDING_REGISTERS["wave_ff_levels"][0], 100)
        rc, out, _err = run(capsys, "params", "save", "--port", s.spec)
        assert rc == 0 and "with the wave and its learned feedforward" in out
    finally:
        s.stop()
    s = SilStage(tmp_path, flash=s.flash)
    try:
        ctl = connect(s.spec)
        st = ctl.status()
        assert st["wave_ff_n_live"] == 200 and st["wave_running"] == 0    # loaded, not started
        assert ctl.params_state()["wave"] == "saved"
        h = interface.HOLDING_REGISTERS
        assert ctl.client.read_holding(h["wave_kind"][0], 3) == [interface.ENUMS["wave_kind"]["triangle"], 0, 8000]
        assert ctl.client.read_holding(h["wave_ff_levels"][0], 100) == staged   # the entries, restored
        rc, res = run_json(capsys, "params", "get", "--port", s.spec, "pid_kp")
        assert res["state"]["wave"] == "saved"
        rc, res = run_json(capsys, "wave", "--saved", "--port", s.spec)
        assert rc == 0 and res["kind"] == "triangle" and res["learned_ff_entries"] == 200 and res["running"]
        rc, _out, err = run(capsys, "wave", "--saved", "--port", s.spec, "--amplitude", "1")
        assert rc == 2 and "takes no --amplitude" in err
        run(capsys, "wave", "--stop", "--port", s.spec)
    finally:
        s.stop()


def test_wave_learn_then_save_and_play_after_a_restart(tmp_path, capsys):
    """wave --learn: a correction learned for the user's periodic wave through
    the closed loop, played with it; params save keeps both over a restart."""
    s = SilStage(tmp_path)
    try:
        assert run(capsys, "params", "set", "--port", s.spec, *GAINS)[0] == 0
        assert run_json(capsys, "servo", "on", "--port", s.spec)[0] == 0
        # refused before anything is written: a chirp, a notch-less controller without --learn-cut
        rc, _out, err = run(capsys, "wave", "--port", s.spec, "--kind", "chirp", "--freq", "1", "--freq-end", "5",
                            "--duration", "1", "--amplitude", "2", "--learn", "3", "--learn-cut", "100")
        assert rc == 2 and "periodic wave" in err
        rc, _out, err = run(capsys, "wave", "--port", s.spec, "--kind", "triangle", "--freq", "10",
                            "--amplitude", "2", "--learn", "3")
        assert rc == 2 and "--learn-cut" in err
        assert connect(s.spec).status()["wave_running"] == 0 and connect(s.spec).status()["wave_ff_n_live"] == 0
        rc, res = run_json(capsys, "wave", "--port", s.spec, "--kind", "triangle", "--freq", "10",
                           "--amplitude", "2", "--learn", "12", "--learn-cut", "50")
        assert rc == 0 and res["running"], res
        lr = res["learned"]
        # the loop's own error at 10 Hz with these low gains is large; the learning must cut it
        # (measured 1114 -> 75 nm after 12 trials: 0.07)
        assert lr["best_rms_um"] <= 0.3 * lr["first_rms_um"], lr
        assert connect(s.spec).status()["wave_ff_n_live"] == lr["n_entries"] > 0
        run(capsys, "wave", "--stop", "--port", s.spec)
        assert run(capsys, "servo", "off", "--port", s.spec, "--disarm")[0] == 0
        rc, out, _err = run(capsys, "params", "save", "--port", s.spec)
        assert rc == 0 and "with the wave and its learned feedforward" in out
    finally:
        s.stop()
    s = SilStage(tmp_path, flash=s.flash)
    try:
        assert connect(s.spec).status()["wave_ff_n_live"] == lr["n_entries"]
        assert run_json(capsys, "servo", "on", "--port", s.spec)[0] == 0   # the gains came from flash too
        rc, res = run_json(capsys, "wave", "--saved", "--port", s.spec, "--record", str(tmp_path / "run.csv"),
                           "--duration", "1.5")
        assert rc == 0 and res["kind"] == "triangle" and res["learned_ff_entries"] == lr["n_entries"]
        import numpy as np
        from piezoctl.io.recording import load_recording
        rec = load_recording(tmp_path / "run.csv")
        e = (rec.reference - rec.y)[rec.t >= rec.t[0] + 1.0]             # the last 5 periods (settled)
        assert np.sqrt(np.mean(e ** 2)) <= 0.5 * lr["first_rms_um"]     # the restarted controller plays it
    finally:
        s.stop()


def test_wave_saved_refused_when_the_controller_holds_none(sil, capsys):
    rc, _out, err = run(capsys, "wave", "--saved", "--port", sil.spec)
    assert rc == 4 and "holds no wave" in err


def test_corrupt_parameter_record_is_ignored_with_its_reason(tmp_path, capsys):
    s = SilStage(tmp_path)
    try:
        run(capsys, "params", "set", "--port", s.spec, "pid_kp=0.25")
        run(capsys, "params", "save", "--port", s.spec)               # slot A, seq 1
        run(capsys, "params", "set", "--port", s.spec, "pid_kp=0.5")
        run(capsys, "params", "save", "--port", s.spec)               # slot B, seq 2
    finally:
        s.stop()
    pfile = pathlib.Path(str(s.flash) + ".params")
    raw = bytearray(pfile.read_bytes())
    assert len(raw) == 2 * interface.PARAMS_SLOT_BYTES
    raw[interface.PARAMS_SLOT_BYTES + 16 + 10] ^= 0x04                # a bit of slot B's payload
    pfile.write_bytes(bytes(raw))
    s = SilStage(tmp_path, flash=s.flash)
    try:
        rc, out, _err = run(capsys, "params", "get", "--port", s.spec, "pid_kp")
        assert rc == 0 and "a stored record was ignored at boot: bad_crc" in out
        res = run_json(capsys, "params", "get", "--port", s.spec)[1]
        assert res["state"]["ignored"] == "bad_crc" and res["state"]["seq"] == 1
        assert res["params"]["pid_kp"]["value"] == 0.25               # the older, intact record
    finally:
        s.stop()
    raw[16 + 10] ^= 0x04                                              # slot A too
    pfile.write_bytes(bytes(raw))
    s = SilStage(tmp_path, flash=s.flash)
    try:
        res = run_json(capsys, "params", "get", "--port", s.spec)[1]
        assert res["state"]["source"] == "defaults" and res["state"]["ignored"] == "bad_crc"
        assert res["params"]["pid_kp"]["value"] == 0
        assert run_json(capsys, "params", "load", "--port", s.spec)[0] == 4   # none_stored: nothing to load
    finally:
        s.stop()


def test_params_bad_input_changes_nothing(sil, capsys):
    before = connect(sil.spec).read_params()
    for argv, msg in ((["pid_kp=200"], "outside what the register holds"), (["nosuch=1"], "unknown parameter"),
                      (["pid_kp=abc"], "not a number"), (["shaper=1,2"], "3 comma-separated"),
                      (["bad_limit=1.5"], "integer"), (["pid_kp"], "NAME=VALUE")):
        rc, _out, err = run(capsys, "params", "set", "--port", sil.spec, *argv)
        assert rc == 2 and msg in err, (argv, err)
    # a value the controller refuses (bad_limit 0): all or nothing
    rc, _out, err = run(capsys, "params", "set", "--port", sil.spec, "pid_kp=0.01", "bad_limit=0")
    assert rc == 4 and "refused" in err
    # more taps than the dynamics inverse holds (32), a wider spacing than 8: refused by the controller
    for bad in ("dyninv_taps=33", "dyninv_ticks=9"):
        rc, _out, err = run(capsys, "params", "set", "--port", sil.spec, "pid_kp=0.01", bad)
        assert rc == 4 and "refused" in err, (bad, err)
    assert connect(sil.spec).read_params() == before
    # armed: refused before anything is written
    run(capsys, "params", "set", "--port", sil.spec, *GAINS)
    run(capsys, "servo", "on", "--port", sil.spec)
    rc, _out, err = run(capsys, "params", "set", "--port", sil.spec, "pid_kp=0.01")
    assert rc == 4 and "disarmed" in err
    rc, _out, err = run(capsys, "params", "save", "--port", sil.spec)
    assert rc == 4 and "armed" in err
    rc, res = run_json(capsys, "servo", "off", "--disarm", "--port", sil.spec)
    assert rc == 0 and not res["armed"]
    assert run(capsys, "params", "set", "--port", sil.spec, "pid_kp=0.01")[0] == 0


def test_params_round_trip_through_a_file(sil, capsys, tmp_path):
    run(capsys, "params", "set", "--port", sil.spec, "pid_kp=0.3", "notch_on=1")
    out = run(capsys, "params", "get", "--port", sil.spec, "--json")[1]
    run(capsys, "params", "defaults", "--port", sil.spec)
    (tmp_path / "p.json").write_text(out)
    assert run(capsys, "params", "set", "--port", sil.spec, "--from", str(tmp_path / "p.json"))[0] == 0
    assert run_json(capsys, "params", "get", "--port", sil.spec)[1]["params"] == json.loads(out)["params"]


# ---------------------------------------------------------------- tables
def test_tables_list_and_rollback(sil, capsys, tmp_path):
    rc, res = run_json(capsys, "tables", "list", "--port", sil.spec)
    assert rc == 0 and all(res[k] is None for k in ("active", "previous", "staged", "coupling"))
    rc, _out, err = run(capsys, "tables", "rollback", "--port", sil.spec)
    assert rc == 4 and "no_previous" in err
    a, _ = dcc_image(version=11)
    b, _ = eupi_image(version=12)
    for n, img in (("a", a), ("b", b)):
        (tmp_path / f"{n}.bin").write_bytes(img)
        rc, res = run_json(capsys, "flash", "--port", sil.spec, str(tmp_path / f"{n}.bin"))
        assert rc == 0 and res["crc"] == int.from_bytes(img[-4:], "little")
    rc, res = run_json(capsys, "tables", "list", "--port", sil.spec)
    assert (res["active"]["kind"], res["active"]["version"]) == ("eupi_inverse", 12)
    assert (res["previous"]["kind"], res["previous"]["version"]) == ("kp_dcc", 11)
    assert res["previous"]["crc"] == int.from_bytes(a[-4:], "little")
    assert res["active"]["stage"]["axis"] == 0 and res["active"]["stage"]["drive_max_v"] == 150.0
    # an upload staged by another connection, not committed
    other = connect(sil.spec)
    other.upload_table(a)
    res = run_json(capsys, "tables", "list", "--port", sil.spec)[1]
    assert res["staged"]["bytes"] == len(a) and res["staged"]["version"] == 11
    assert res["staged"]["crc"] == int.from_bytes(a[-4:], "little") and res["staged"]["kind"] == "kp_dcc"
    other.client.close()
    rc, res = run_json(capsys, "tables", "rollback", "--port", sil.spec)
    assert rc == 0 and res["after"]["active"]["version"] == 11 and res["after"]["previous"] is None
    rc, _out, err = run(capsys, "tables", "rollback", "--port", sil.spec)
    assert rc == 4 and "no_previous" in err and "keeps running" in err


def test_controller_flash_refusal_raises_controller_refused(sil):
    from piezoctl.tables.build import ctl_section, kp_dcc_sections
    from piezoctl.fixtures.ctl import DCC_LINE
    from piezoctl.tables.image import build_image
    _img, d = dcc_image()
    valve = build_image("kp_dcc", [ctl_section(*DCC_LINE)] + kp_dcc_sections(d),
                        drive_range_v=(-90.0, 90.0), position_range_um=(-6.0, 4.0))
    ctl = connect(sil.spec)
    with pytest.raises(ControllerRefused, match="wrong_stage"):
        ctl.flash(valve)
    assert ctl.status()["active_table_crc"] == 0
    img, _ = dcc_image(version=3)
    steps = []
    res = ctl.flash(img, progress=lambda step, done, total: steps.append(step))
    assert res["kind"] == "kp_dcc" and res["version"] == 3 and ctl.status()["active_table_crc"] == res["crc"]
    assert {"upload", "verify"} <= set(steps)
