"""``piezoctl record``: read the controller's recorder into a recording CSV.

``record`` records what the controller does now for ``--duration`` seconds.
The decimation is chosen from the duration and the recorder's capacity
(``rec_capacity`` samples shared by the channels) unless given; ``--stream``
reads the recorder while it runs, as a ring, so a capture of any length works
(frames the link could not keep up with are reported as lost). Recordings are
written in the project's recording format (``docs/recordings.md``): ``t``
[s], ``u`` drive [V], ``y`` position [um], and ``reference`` [um], ``u2``
[V], ``x2`` [um] when recorded, so ``piezoctl identify`` reads them directly.
``--plot FILE.png`` also draws it. Contract: ``docs/wave-record.md``.

The capture helpers here are shared with ``piezoctl wave --record``
(:mod:`piezoctl.commands.wave`). numpy, matplotlib and the device module are
imported inside the functions that need them: ``piezoctl --help`` stays fast.
"""

from __future__ import annotations

import math
import os

from ..errors import CliError
from ._options import Progress, add_output, add_port, emit, progress

__all__ = ["COLUMNS", "SIGNAL_NAMES", "MAX_DECIMATION", "add_capture_options", "parse_signals",
           "choose_decimation", "check_writable", "record", "write_recording", "plot_recording"]

# recorder signal -> recording column (docs/recordings.md)
COLUMNS = {"u": "u", "y": "y", "ref": "reference", "u2": "u2", "y2": "x2", "err": "err", "ff": "ff", "fb": "fb"}
SIGNAL_NAMES = ("ref", "y", "u", "err", "ff", "fb", "y2", "u2")  # device.SIGNALS, without importing it
MAX_DECIMATION = 65535  # rec_decimation is a uint16 >= 1
PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def add_capture_options(p, *, duration_required: bool) -> None:
    """``--signals``, ``--duration``, ``--decimation``, ``--stream``, ``--plot``."""
    p.add_argument("--signals", default="ref,y,u",
                   help="comma-separated: ref,y,u,err,ff,fb,y2,u2 (default ref,y,u)")
    p.add_argument("--duration", type=float, required=duration_required, metavar="S",
                   help="how long to record [s]")
    p.add_argument("--decimation", default="auto", metavar="N|auto",
                   help="keep every N-th tick; auto (default): 1 if the duration fits the recorder, "
                        "else the smallest N that fits it (1 with --stream)")
    p.add_argument("--stream", action="store_true",
                   help="read the recorder while it runs (ring), for captures longer than it holds; "
                        "lost frames are reported")
    p.add_argument("--plot", metavar="FILE.png", help="also draw the recording (png, svg or pdf)")
    p.add_argument("--session", metavar="LABEL",
                   help="sensor session label written as the `session` metadata: recordings with the same label "
                        "share the sensor's zero (docs/recordings.md)")


def parse_signals(text: str) -> list[str]:
    """``"ref,y,u"`` -> ``["ref", "y", "u"]``; refuses unknown, repeated or too many signals."""
    sigs = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in sigs if s not in SIGNAL_NAMES]
    if bad:
        raise CliError(f"unknown signal(s) {', '.join(bad)}; known: {', '.join(SIGNAL_NAMES)}")
    if not sigs:
        raise CliError("--signals names no signal")
    if len(set(sigs)) != len(sigs):
        raise CliError(f"--signals names a signal twice: {text}")
    if len(sigs) > 8:
        raise CliError("the recorder keeps at most 8 signals")
    return sigs


def choose_decimation(duration_s: float, n_signals: int, tick_hz: float, capacity_samples: int,
                      requested: str | int = "auto", stream: bool = False) -> tuple[int, int, str]:
    """Decimation and frame count for a capture of ``duration_s`` [s].

    Parameters
    ----------
    duration_s : float
        Capture length [s], > 0.
    n_signals : int
        Recorded signals (channels), 1..8.
    tick_hz : float
        Control-loop rate [Hz].
    capacity_samples : int
        The recorder's buffer (``rec_capacity``) [samples of all channels].
    requested : ``"auto"`` or int
        ``auto``: 1 when the capture fits the buffer at full rate (or with
        ``stream``), else the smallest decimation whose frames fit it.
    stream : bool
        The capture is streamed (any number of frames).

    Returns
    -------
    decimation : int
        Ticks per recorded frame, 1..65535.
    frames : int
        Frames to record: ``round(duration_s * tick_hz / decimation)``, >= 1.
    why : str
        One line saying what was chosen and why.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise CliError(f"--duration must be a positive number of seconds (got {duration_s:g})")
    cap = capacity_samples // n_signals
    ticks = duration_s * tick_hz
    auto = str(requested) == "auto"
    if auto:
        dec = 1 if stream else max(1, math.ceil(ticks / cap))
        while not stream and round(ticks / dec) > cap:
            dec += 1
    else:
        try:
            dec = int(requested)
        except ValueError:
            raise CliError(f"--decimation must be auto or a whole number 1..{MAX_DECIMATION} "
                           f"(got {requested!r})") from None
        if not 1 <= dec <= MAX_DECIMATION:
            raise CliError(f"--decimation must be 1..{MAX_DECIMATION} (got {dec})")
    if dec > MAX_DECIMATION:
        raise CliError(f"{duration_s:g} s does not fit the recorder even at decimation {MAX_DECIMATION}: "
                       "use --stream")
    frames = int(round(ticks / dec))
    if frames < 1:
        raise CliError(f"{duration_s:g} s is shorter than one sample at decimation {dec} "
                       f"({dec / tick_hz:g} s per sample)")
    if not stream and frames > cap:
        need = max(1, math.ceil(ticks / cap))
        raise CliError(f"{duration_s:g} s at decimation {dec} is {frames} frames of {n_signals} signal(s); "
                       f"the recorder holds {cap} ({capacity_samples} samples): use --decimation {need} "
                       "or more, a shorter --duration, or --stream")
    rate = tick_hz / dec
    how = "chosen" if auto else "given"
    why = (f"decimation {dec} ({how}): {frames} frames at {rate:g} Hz of {n_signals} signal(s)"
           + (", streamed" if stream else f", the recorder holds {cap}"))
    return dec, frames, why


def check_writable(path: str | None, what: str, suffixes: tuple[str, ...] | None = None) -> None:
    """Refuse an output path before anything is done: missing folder, wrong suffix, a folder."""
    if path is None:
        return
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CliError(f"{what} {path}: folder {folder} does not exist")
    if os.path.isdir(path):
        raise CliError(f"{what} {path} is a folder")
    if suffixes and os.path.splitext(path)[1].lower() not in suffixes:
        raise CliError(f"{what} {path}: want a {', '.join(suffixes)} file")


def record(args, ctl, signals: list[str], duration_s: float, out: str, *, start_wave: bool = False) -> dict:
    """Capture ``signals`` for ``duration_s`` [s] as ``args`` ask; write ``out`` and ``args.plot``.

    The recorder is armed here; with ``start_wave`` the loaded wave is
    started and fires its (software) trigger, so ``t = 0`` is the wave's
    first sample. Returns the result fields of ``--json``.
    """
    label = getattr(args, "session", None)
    if label is not None and (not label.strip() or any(c in label for c in "\r\n")):
        raise CliError(f"--session must be a non-empty label on one line (got {label!r})")
    dec, frames, why = choose_decimation(duration_s, len(signals), ctl.identity.tick_hz,
                                         ctl.identity.rec_capacity, args.decimation, args.stream)
    progress(args, why)
    trigger = "software" if start_wave else "immediate"
    lost = 0
    # the controller's tick counter stamps the recording on the session clock (docs/recordings.md:
    # session_time_s; the diagnosis runs thermal drift on it across recordings)
    session_s = ctl.status()["tick_count"] / float(ctl.identity.tick_hz)
    with Progress(args, f"record {duration_s:g} s"):
        if args.stream:
            last = [0.0]

            def report(done: int, total: int) -> None:
                if done - last[0] >= 0.1 * total:  # every tenth of the capture
                    last[0] = done
                    progress(args, f"{done}/{total} frames")

            raw, lost = ctl.stream(signals, frames, decimation=dec, trigger=trigger,
                                   start_wave=start_wave, progress=report)
        else:
            raw = ctl.capture(signals, frames, decimation=dec, trigger=trigger, start_wave=start_wave)
    cols = {"t": raw["t"], **{COLUMNS[s]: raw[s] for s in signals}}
    write_recording(out, cols, ctl.identity.tick_hz / dec, session_s, label)
    if args.plot:
        with Progress(args, f"plot {args.plot}"):
            plot_recording(args.plot, cols, title=f"{os.path.basename(out)}: {duration_s:g} s, "
                                                  f"{ctl.identity.tick_hz / dec:g} Hz")
    return {"out": out, "signals": signals, "columns": list(cols), "frames": int(len(cols["t"])),
            "frames_wanted": frames, "lost_frames": lost, "decimation": dec,
            "decimation_chosen": str(args.decimation) == "auto",
            "sample_rate_hz": ctl.identity.tick_hz / dec, "duration_s": duration_s,
            "stream": bool(args.stream), "plot": args.plot}


def write_recording(path: str, cols: dict, rate_hz: float, session_s: float | None = None,
                    session: str | None = None) -> None:
    """Write ``cols`` (``t`` and recording columns) as a recording CSV at ``rate_hz`` [Hz]; ``session_s`` [s]:
    the controller's time since start when the capture began (metadata ``session_time_s``); ``session``: the
    sensor session's label (metadata ``session``)."""
    from ..io.recording import write_csv

    names = ["t"] + [c for c in ("u", "y", "reference", "u2", "x2", "err", "ff", "fb") if c in cols]
    meta = {"sample_rate_hz": f"{rate_hz:g}", "source": "piezoctl record"}
    if session_s is not None:
        meta["session_time_s"] = f"{session_s:.4f}"
    if session:
        meta["session"] = str(session)
    write_csv(path, {n: cols[n] for n in names}, meta=meta)


# column -> (panel, unit): positions, drives and the error each get a panel
_PANELS = {"reference": ("position", "um"), "y": ("position", "um"), "x2": ("position", "um"),
           "u": ("drive", "V"), "u2": ("drive", "V"), "ff": ("drive", "V"), "fb": ("drive", "V"),
           "err": ("error", "um")}


def plot_recording(path: str, cols: dict, title: str = "") -> None:
    """Draw a recording: one panel per unit (position [um], drive [V], error [um]) against t [s]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels: dict[str, list[str]] = {}
    for name in cols:
        if name in _PANELS:
            panels.setdefault(_PANELS[name][0], []).append(name)
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(9, 2.4 * len(panels) + 0.6), squeeze=False)
    for ax, (panel, names) in zip(axes[:, 0], panels.items()):
        for name in names:
            ax.plot(cols["t"], cols[name], lw=0.8, label=name)
        ax.set_ylabel(f"{panel} [{_PANELS[names[0]][1]}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def add_parser(sub) -> None:
    r = sub.add_parser("record", help="record controller signals for a duration into a recording CSV",
                       description="Record what the controller does now. The decimation is chosen from "
                                   "the duration and the recorder's capacity unless given; --stream reads "
                                   "the recorder while it runs for captures longer than it holds.")
    add_port(r)
    add_capture_options(r, duration_required=True)
    r.add_argument("--out", required=True, metavar="REC.csv", help="the recording (docs/recordings.md)")
    add_output(r)
    r.set_defaults(func=run_record)


def run_record(args) -> int:
    from ..device import connect

    sigs = parse_signals(args.signals)
    check_writable(args.out, "--out")
    check_writable(args.plot, "--plot", PLOT_SUFFIXES)
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise CliError(f"--duration must be a positive number of seconds (got {args.duration:g})")
    ctl = connect(args.port)
    res = record(args, ctl, sigs, args.duration, args.out)
    res["port"] = args.port
    emit(args, res, _record_lines(res))
    return 0


def _record_lines(res: dict) -> list[str]:
    lines = [f"{res['out']}: {res['frames']} samples of {', '.join(res['signals'])} at "
             f"{res['sample_rate_hz']:g} Hz (decimation {res['decimation']}"
             f"{', chosen' if res['decimation_chosen'] else ''})"]
    if res["stream"]:
        lines.append(f"lost frames: {res['lost_frames']} of {res['frames_wanted']}"
                     + (" (the link did not keep up: a larger --decimation or fewer --signals)"
                        if res["lost_frames"] else ""))
    if res["plot"]:
        lines.append(f"plot: {res['plot']}")
    return lines
