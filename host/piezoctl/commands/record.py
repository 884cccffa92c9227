"""``piezoctl record`` and ``piezoctl wave``: drive the wave generator, read the recorder.

``wave`` loads and starts the wave generator (amplitudes in drive volts for
open-loop excitation without a table, or in micrometres of position); with
``--record OUT.csv`` it also records the run. ``record`` records what the
controller does now for a duration. Recordings are written in the project's
recording format (``docs/recordings.md``): ``t`` [s], ``u`` drive [V], ``y``
position [um], and ``reference`` [um], ``u2`` [V], ``x2`` [um] when recorded,
so ``piezoctl identify`` reads them directly.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from ..device import MODES, SIGNALS, WAVE_KINDS, connect
from ..errors import CliError
from ..io.recording import write_csv

# recorder signal -> recording column (docs/recordings.md)
COLUMNS = {"u": "u", "y": "y", "ref": "reference", "u2": "u2", "y2": "x2", "err": "err", "ff": "ff", "fb": "fb"}


def capture(ctl, signals: list[str], duration_s: float, *, decimation: int = 1, start_wave: bool = False) -> dict:
    """Record ``signals`` for ``duration_s`` [s]; columns named as in a recording CSV."""
    frames = int(round(duration_s * ctl.identity.tick_hz / decimation))
    cols = ctl.capture(signals, frames, decimation=decimation,
                       trigger="software" if start_wave else "immediate", start_wave=start_wave)
    return {"t": cols["t"], **{COLUMNS[s]: cols[s] for s in signals}}


def write_recording(path: str, cols: dict, ctl) -> None:
    names = ["t"] + [c for c in ("u", "y", "reference", "u2", "x2", "err", "ff", "fb") if c in cols]
    rate = 1.0 / (cols["t"][1] - cols["t"][0]) if len(cols["t"]) > 1 else float(ctl.identity.tick_hz)
    meta = {"sample_rate_hz": f"{rate:g}", "source": "piezoctl record"}
    write_csv(path, {n: cols[n] for n in names}, meta=meta)


def add_parser(sub) -> None:
    r = sub.add_parser("record", help="record controller signals for a duration into a recording CSV")
    r.add_argument("--port", required=True)
    r.add_argument("--signals", default="ref,y,u", help="comma-separated: ref,y,u,err,ff,fb,y2,u2 (default ref,y,u)")
    r.add_argument("--duration", type=float, required=True, help="[s]")
    r.add_argument("--decimation", type=int, default=1)
    r.add_argument("--out", required=True, metavar="REC.csv")
    r.set_defaults(func=run_record)

    w = sub.add_parser("wave", help="load and start the wave generator (optionally recording the run)")
    w.add_argument("--port", required=True)
    w.add_argument("--kind", choices=[k for k in WAVE_KINDS if k != "off"], required=True)
    unit = w.add_mutually_exclusive_group()
    unit.add_argument("--volts", action="store_true", help="amplitude and offset are drive [V] (open loop, no table)")
    w.add_argument("--amplitude", type=float, default=0.0, help="peak [um, or V with --volts]")
    w.add_argument("--offset", type=float, default=None, help="centre [um, or V] (default: mid-range)")
    w.add_argument("--freq", type=float, default=1.0, help="[Hz]; chirp start")
    w.add_argument("--freq-end", type=float, help="chirp end [Hz]")
    w.add_argument("--cycles", type=int, default=0, help="periods to play, 0 = endless")
    w.add_argument("--duration", type=float, help="chirp duration; with --record, how long to record [s]")
    w.add_argument("--mode", choices=list(MODES), help="set the control mode first (disarms and re-arms)")
    w.add_argument("--record", metavar="OUT.csv", help="record ref,y,u during the run")
    w.add_argument("--stop", action="store_true", help="stop the wave generator and exit")
    w.set_defaults(func=run_wave)


def run_record(args) -> int:
    sigs = [s.strip() for s in args.signals.split(",") if s.strip()]
    bad = [s for s in sigs if s not in SIGNALS]
    if bad:
        raise CliError(f"unknown signal(s) {', '.join(bad)}; known: {', '.join(SIGNALS)}")
    ctl = connect(args.port)
    cols = capture(ctl, sigs, args.duration, decimation=args.decimation)
    write_recording(args.out, cols, ctl)
    print(f"{args.out}: {len(cols['t'])} samples of {', '.join(sigs)}")
    return 0


def run_wave(args) -> int:
    ctl = connect(args.port)
    if args.stop:
        ctl.command("stop_wave")
        return 0
    sc = ctl.scale
    if args.volts:
        off = args.offset if args.offset is not None else 0.5 * (sc.drive_min_v + sc.drive_max_v)
        amp_q = int(round(args.amplitude / (0.5 * (sc.drive_max_v - sc.drive_min_v)) * 32768))
        off_q = ctl.q15_drive(off)
    else:
        off = args.offset if args.offset is not None else sc.p_mid
        amp_q = int(round(args.amplitude / sc.p_half * 32768))
        off_q = ctl.q15_position(off)
    if not 0 <= amp_q <= 32767:
        raise CliError("the amplitude exceeds the controller's range")
    if args.kind == "chirp" and (args.freq_end is None or args.duration is None):
        raise CliError("a chirp needs --freq-end and --duration")
    if args.mode:
        ctl.arm(False)
        ctl.set_mode(args.mode)
        ctl.arm(True)
    ctl.configure_wave(args.kind, offset_q15=off_q, amplitude_q15=amp_q, f_hz=args.freq,
                       f_end_hz=args.freq_end, duration_s=args.duration, cycles=args.cycles,
                       tones=[(amp_q, args.freq, 0.0)] if args.kind == "multisine" else None)
    if args.record:
        dur = args.duration or (args.cycles / args.freq if args.cycles else 1.0)
        cols = capture(ctl, ["ref", "y", "u"], dur, start_wave=True)
        write_recording(args.record, cols, ctl)
        print(f"{args.record}: {len(cols['t'])} samples")
    else:
        ctl.command("start_wave")
        print(f"wave {args.kind} running on {args.port}", file=sys.stderr)
    return 0
