"""``piezoctl wave`` and ``piezoctl record`` against the SIL virtual controller.

The wave generator's output is recorded as the reference (signal ``ref``)
and compared with what was asked: a triangle exactly (its integer formula,
``firmware/core/wave.c``), tones and file waves to a few LSB. Streaming is
checked frame by frame over captures longer than the recorder holds, and a
reader too slow on purpose must report lost frames and never pass an
overwritten frame as good. Nonsense options are refused in one line and
leave the controller's wave registers as they were.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from piezoctl import cli, interface
from piezoctl.commands.record import choose_decimation
from piezoctl.commands.wave import parse_tones
from piezoctl.device import connect, freq_word
from piezoctl.errors import CliError
from piezoctl.io.recording import load_recording

from sil_fixture import sil  # noqa: F401  (pytest fixture)

TICK = 10000
CAP = 65536  # sil-stage's rec_capacity [samples]


def run(capsys, *argv):
    """Run the CLI; returns (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def triangle_q15(n: np.ndarray, fw: int, off: int, amp: int) -> np.ndarray:
    """The generator's triangle at samples n (wave.c: phase n * fw, start at 0 rising)."""
    q = (n.astype(np.uint64) * np.uint64(fw) + np.uint64(0x40000000)) & np.uint64(0xFFFFFFFF)
    q = q.astype(np.int64)
    shape = np.where(q < 2**31, (q >> 15) - 32768, 32767 - ((q - 2**31) >> 15))
    return np.clip(off + ((amp * shape + (1 << 14)) >> 15), -32768, 32767)


# ---------------------------------------------------------------- pure functions

def test_decimation_is_chosen_from_capacity_and_duration():
    cap3 = CAP // 3
    dec, frames, why = choose_decimation(2.0, 3, TICK, CAP)
    assert (dec, frames) == (1, 20000) and "chosen" in why
    dec, frames, _ = choose_decimation(10.0, 3, TICK, CAP)
    # the smallest decimation that fits: 100000 ticks / 21845 frames -> 5
    assert dec == 5 and frames == 20000 <= cap3
    assert round(10.0 * TICK / (dec - 1)) > cap3
    dec, frames, _ = choose_decimation(60.0, 8, TICK, CAP)
    assert frames <= CAP // 8 and round(60.0 * TICK / (dec - 1)) > CAP // 8
    # streamed: full rate, any length
    assert choose_decimation(60.0, 3, TICK, CAP, stream=True)[:2] == (1, 600000)
    assert choose_decimation(1.0, 3, TICK, CAP, requested="7")[:2] == (7, 1429)


@pytest.mark.parametrize("dur,dec,stream,msg", [
    (0.0, "auto", False, "positive"),
    (-1.0, "auto", False, "positive"),
    (float("nan"), "auto", False, "positive"),
    (5.0, "1", False, "use --decimation 3 or more"),
    (1.0, "0", False, "1..65535"),
    (1.0, "x", False, "auto or a whole number"),
    (1e-5, "auto", False, "shorter than one sample"),
    (1e6, "auto", False, "use --stream"),
])
def test_decimation_refusals(dur, dec, stream, msg):
    with pytest.raises(CliError, match=msg):
        choose_decimation(dur, 3, TICK, CAP, requested=dec, stream=stream)


def test_tones_parse_and_refusals():
    tones = parse_tones("10:0.5, 37:0.3:90", TICK)
    assert tones == [(10.0, 0.5, 0.0), (37.0, 0.3, pytest.approx(math.pi / 2))]
    for bad, msg in [("10:0", "amplitude .* must be > 0"), ("-3:1", "must be > 0 Hz"),
                     ("5000:1", "Nyquist"), ("10", "FREQ:AMPLITUDE"), ("a:b", "not numbers"),
                     (",".join(f"{k + 1}:0.1" for k in range(9)), "at most 8"), ("", "no tone")]:
        with pytest.raises(CliError, match=msg):
            parse_tones(bad, TICK)


# ---------------------------------------------------------------- against the SIL

def wave_registers(spec: str) -> list[int]:
    """wave_kind .. wave_hold_ticks and the first tone and levels: what a refused wave must not touch."""
    ctl = connect(spec)
    h = interface.HOLDING_REGISTERS
    return (ctl.client.read_holding(h["wave_kind"][0], 15) + ctl.client.read_holding(h["wave_tones"][0], 10)
            + ctl.client.read_holding(h["wave_levels"][0], 8))


def test_stop_works_alone(sil, capsys):
    assert run(capsys, "wave", "--port", sil.spec, "--kind", "sine", "--amplitude", "1", "--freq", "20")[0] == 0
    ctl = connect(sil.spec)
    assert ctl.status()["wave_running"] == 1
    code, out, _ = run(capsys, "wave", "--port", sil.spec, "--stop", "--json")
    assert code == 0 and json.loads(out) == {"port": sil.spec, "stopped": True}
    assert ctl.status()["wave_running"] == 0
    code, _, err = run(capsys, "wave", "--port", sil.spec, "--stop", "--kind", "sine")
    assert code == 2 and "--stop takes no wave options" in err


@pytest.mark.parametrize("args,msg", [
    (["--kind", "sine", "--amplitude", "0"], "--amplitude must be > 0"),
    (["--kind", "sine", "--amplitude", "-1"], "--amplitude must be > 0"),
    (["--kind", "sine"], "--amplitude must be > 0 (got none)"),
    (["--kind", "sine", "--amplitude", "1", "--freq", "-5"], "--freq must be > 0 Hz"),
    (["--kind", "triangle", "--amplitude", "1", "--freq", "5000"], "Nyquist frequency 5000 Hz"),
    (["--kind", "chirp", "--amplitude", "1", "--freq", "1"], "a chirp needs an end"),
    (["--kind", "chirp", "--amplitude", "1", "--freq", "1", "--freq-end", "50"], "--duration"),
    (["--kind", "chirp", "--amplitude", "1", "--freq", "50", "--freq-end", "10", "--duration", "1"], "upward"),
    (["--kind", "sine", "--amplitude", "50"], "outside the controller's range"),
    (["--kind", "sine", "--amplitude", "1", "--cycles", "-1"], "--cycles must be >= 0"),
    (["--tones", "10:8,20:8"], "outside the controller's range"),
    (["--tones", "10:0"], "must be > 0"),
    (["--tones", "10:1", "--cycles", "3"], "plays it until stopped"),
    (["--kind", "multisine"], "needs --tones"),
    (["--kind", "sine", "--tones", "10:1"], "makes a multisine"),
    (["--kind", "arbitrary"], "needs --file"),
    ([], "say which wave"),
])
def test_nonsense_is_refused_and_changes_nothing(sil, capsys, args, msg):
    before = wave_registers(sil.spec)
    code, out, err = run(capsys, "wave", "--port", sil.spec, *args)
    assert code == 2, err
    assert msg in err and err.count("\n") == 1 and "Traceback" not in err
    assert wave_registers(sil.spec) == before


def test_triangle_recorded_exactly(sil, capsys, tmp_path):
    out = tmp_path / "tri.csv"
    code, stdout, _ = run(capsys, "wave", "--port", sil.spec, "--kind", "triangle", "--amplitude", "6",
                          "--offset", "10", "--freq", "7", "--record", str(out), "--duration", "0.3",
                          "--signals", "ref", "--json")
    assert code == 0
    res = json.loads(stdout)
    assert res["running"] and res["record"]["decimation"] == 1 and res["record"]["frames"] == 3000
    ctl = connect(sil.spec)
    rec = _rows(out)
    ref_q = np.array([ctl.q15_position(v) for v in rec[:, 1]])
    want = triangle_q15(np.arange(len(ref_q)), freq_word(7, TICK), ctl.q15_position(10.0),
                        int(math.floor(6 / ctl.scale.p_half * 32768 + 0.5)))
    assert np.array_equal(ref_q, want)


def test_multitone_matches_its_tones(sil, capsys, tmp_path):
    out = tmp_path / "ms.csv"
    code, stdout, _ = run(capsys, "wave", "--port", sil.spec, "--tones", "10:2,37:1.5:90", "--offset", "10",
                          "--record", str(out), "--duration", "0.2", "--json")
    assert code == 0
    res = json.loads(stdout)
    assert res["kind"] == "multisine" and [t["freq_hz"] for t in res["tones"]] == [10.0, 37.0]
    rec = load_recording(out)
    t = np.arange(len(rec.t)) / TICK
    want = 10 + 2 * np.sin(2 * np.pi * 10 * t) + 1.5 * np.sin(2 * np.pi * 37 * t + np.pi / 2)
    lsb = connect(sil.spec).scale.p_half / 32768
    # each tone's amplitude and the LUT interpolation round to within an LSB or so
    assert np.max(np.abs(rec.reference - want)) < 4 * lsb


def write_wave(path, t, v, column="reference"):
    path.write_text(f"t,{column}\n" + "".join(f"{a:.6f},{b:.6f}\n" for a, b in zip(t, v)))


def test_arbitrary_file_resampled_to_the_hold(sil, capsys, tmp_path):
    f = tmp_path / "w.csv"
    t = np.arange(0, 0.2, 5e-4)  # 400 samples, 2 ticks apart: too many levels at the file's step
    write_wave(f, t, 10 + 4 * np.sin(2 * np.pi * 5 * t))
    before = wave_registers(sil.spec)
    code, _, err = run(capsys, "wave", "--port", sil.spec, "--file", str(f))
    assert code == 2 and "needs 400 levels; the wave generator holds 256" in err
    assert "shorten the file to 0.128 s or pass --hold 0.0008" in err
    assert wave_registers(sil.spec) == before
    # at the hold the message proposes, it plays: 250 levels of 8 ticks
    out = tmp_path / "arb.csv"
    code, stdout, _ = run(capsys, "wave", "--port", sil.spec, "--file", str(f), "--hold", "0.0008",
                          "--record", str(out), "--duration", "0.3", "--json")
    assert code == 0
    res = json.loads(stdout)
    assert (res["kind"], res["levels"], res["hold_ticks"]) == ("arbitrary", 250, 8)
    rec = load_recording(out)
    n = np.arange(len(rec.t))
    level_t = ((n // 8) % 250) * 8e-4
    want = 10 + 4 * np.sin(2 * np.pi * 5 * level_t)
    lsb = connect(sil.spec).scale.p_half / 32768
    assert np.max(np.abs(rec.reference - want)) < 3 * lsb


def test_constant_file_is_amplitude_zero(sil, capsys, tmp_path):
    f = tmp_path / "flat.csv"
    write_wave(f, np.arange(10) * 1e-3, np.full(10, 5.0))
    code, _, err = run(capsys, "wave", "--port", sil.spec, "--file", str(f))
    assert code == 2 and "amplitude 0" in err


def test_record_chooses_decimation_and_plots(sil, capsys, tmp_path):
    out, png = tmp_path / "r.csv", tmp_path / "r.png"
    code, stdout, err = run(capsys, "record", "--port", sil.spec, "--duration", "2.5", "--signals",
                            "ref,y,u,err,ff,fb,y2,u2", "--out", str(out), "--plot", str(png), "--json")
    assert code == 0, err
    res = json.loads(stdout)
    # 25000 ticks, 8192 frames of 8 signals: decimation 4 is the smallest that fits
    assert (res["decimation"], res["frames"], res["decimation_chosen"]) == (4, 6250, True)
    rec = load_recording(out)
    assert rec.meta["sample_rate_hz"] == "2500" and len(rec.t) == 6250
    # stamped on the controller's clock: a second capture starts later on it by at least the first's length
    t_first = float(rec.meta["session_time_s"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, _, err = run(capsys, "record", "--port", sil.spec, "--duration", "2.5", "--signals", "ref,y,u,err,ff,fb,y2,u2",
                       "--decimation", "2", "--out", str(out))
    assert code == 2 and "use --decimation 4 or more" in err
    assert "session" not in rec.meta   # only written when the user names the sensor session
    code, _, err = run(capsys, "record", "--port", sil.spec, "--duration", "0.5", "--out", str(out),
                       "--session", "rezeroed-2")
    assert code == 0, err
    assert float(load_recording(out).meta["session_time_s"]) >= t_first + 2.5
    assert load_recording(out).meta["session"] == "rezeroed-2"
    before = out.read_bytes()
    code, _, err = run(capsys, "record", "--port", sil.spec, "--duration", "0.5", "--out", str(out), "--session", " ")
    assert code == 2 and "--session" in err and out.read_bytes() == before


def test_stream_longer_than_the_recorder(sil, capsys, tmp_path):
    """Eight signals at decimation 2: the recorder holds 8192 frames (1.6 s); stream 4 s."""
    out = tmp_path / "s.csv"
    assert run(capsys, "wave", "--port", sil.spec, "--kind", "triangle", "--amplitude", "6", "--offset", "10",
               "--freq", "3", "--record", str(out), "--duration", "4", "--stream", "--decimation", "2",
               "--signals", "ref,y,u,err,ff,fb,y2,u2", "--json")[0] == 0
    ctl = connect(sil.spec)
    rec = _rows(out)
    n = np.round(rec[:, 0] * TICK).astype(np.int64)
    assert n[-1] == 2 * 19999
    assert len(n) > CAP // 8  # more than the recorder holds
    ref_q = np.array([ctl.q15_position(v) for v in rec[:, 3]])  # t,u,y,reference,...
    want = triangle_q15(n, freq_word(3, TICK), ctl.q15_position(10.0),
                        int(math.floor(6 / ctl.scale.p_half * 32768 + 0.5)))
    assert np.array_equal(ref_q, want)  # every frame received is the frame of its time


def test_slow_reader_reports_lost_frames_and_keeps_only_good_ones(sil):
    """A reader slower than the writer: frames are lost, counted, and none passes corrupted."""
    ctl = connect(sil.spec)
    ctl.configure_wave("triangle", offset_q15=0, amplitude_q15=20000, f_hz=2.0)
    inner = ctl.client.read_write

    def slow(*a, **k):
        time.sleep(0.004)
        return inner(*a, **k)

    ctl.client.read_write = slow
    frames = 20000  # 2 s of 8 signals; the ring holds 8192 frames
    cols, lost = ctl.stream(["ref", "y", "u", "err", "ff", "fb", "y2", "u2"], frames,
                            trigger="software", start_wave=True)
    assert lost > 0 and len(cols["t"]) + lost == frames
    n = np.round(cols["t"] * TICK).astype(np.int64)
    ref_q = np.array([ctl.q15_position(v) for v in cols["ref"]])
    assert np.array_equal(ref_q, triangle_q15(n, freq_word(2.0, TICK), 0, 20000))
    assert ctl.status()["rec_state"] == 0  # the ring was reset afterwards


@pytest.mark.parametrize("extra,msg", [
    (["--plot", "x.png"], "--plot applies to --record"),
    (["--stream"], "--stream applies to --record"),
    (["--duration", "2"], "a chirp's length is --duration"),
    (["--signals", "y"], "--signals applies to --record"),
])
def test_capture_options_need_record(sil, capsys, extra, msg):
    code, _, err = run(capsys, "wave", "--port", sil.spec, "--kind", "sine", "--amplitude", "1", *extra)
    assert code == 2 and msg in err


def test_wave_and_record_import_nothing_heavy():
    """``piezoctl --help`` imports every command module: these two must not pull numpy or the device."""
    import subprocess
    import sys

    code = ("import sys, piezoctl.commands.wave, piezoctl.commands.record; "
            "print(','.join(m for m in ('numpy', 'matplotlib', 'piezoctl.device', 'piezoctl.interface') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ""


def _rows(path):
    """The recording's numeric rows (metadata lines and the header skipped, however many metadata lines)."""
    lines = path.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line and not line.startswith("#"))
    return np.loadtxt(lines[header + 1:], delimiter=",", ndmin=2)
