"""``piezoctl wave``: load and start the wave generator, or stop it.

Amplitudes and offsets are micrometres of position, or drive volts with
``--volts`` (open-loop excitation without a table). Kinds: ``sine``,
``triangle``, ``chirp`` (``--freq`` to ``--freq-end`` in ``--duration``
seconds), ``multisine`` (``--tones F:A[:PHASE],...``: up to 8 tones of
frequency [Hz], amplitude and start phase [deg]), ``arbitrary`` (``--file
X.csv``: the file resampled to ``--hold`` seconds per level) and ``steps``
(``--file X.csv``: each row's value held until the next row's time).
``--record OUT.csv`` records the run from the wave's first sample;
``--stop`` stops the generator. ``--learn N`` learns, before starting a
periodic wave, a feedforward correction for it over N trials (iterative
learning control through the closed loop, ``calibrate/ilc.py``: the unit armed
in ``ff_feedback`` or ``feedback``), which the firmware then plays in step
with the wave; ``--learn-cut HZ`` is the band learned (default: twice the
controller's notch frequency). ``--saved`` starts the wave the controller
holds, as loaded at boot from its parameter record (``piezoctl params
save`` keeps the wave and its learned feedforward), without writing a new
one. Contract: ``docs/wave-record.md``.

Values that make no sense are refused before anything is written to the
controller: amplitude 0 or negative, a frequency not in (0, Nyquist), a
chirp without an end or a duration, tones whose sum leaves the range, a
file longer than the generator's level table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import CliError, ControllerRefused
from ._options import add_output, add_port, emit, progress
from .record import PLOT_SUFFIXES, add_capture_options, check_writable, parse_signals, record

__all__ = ["WaveSpec", "parse_tones", "plan_wave", "read_wave_file", "resample_file", "add_parser", "run_wave"]

KINDS = ("sine", "triangle", "multisine", "chirp", "steps", "arbitrary")  # device.WAVE_KINDS but off
MAX_TONES = 8  # PIEZO_WAVE_MAX_TONES (firmware/core/wave.h), also the wave_tones register count / 5


@dataclass
class WaveSpec:
    """A wave the controller can play, in its own integers, and what it means in units.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    offset_q15, amplitude_q15 : int
        Centre and peak (q15 of the position or drive range).
    f_hz, f_end_hz : float
        Frequency [Hz] (sine, triangle, chirp start); chirp end [Hz].
    duration_s : float or None
        Chirp length [s].
    cycles : int
        Periods or passes to play, 0 = endless.
    tones : list of (int, float, float)
        Multisine tones: amplitude q15, frequency [Hz], start phase [rad].
    levels_q15 : list of int
        Steps and arbitrary: the shape values (q15, scaled by the amplitude).
    durations_ticks : list of int
        Steps: ticks per level.
    hold_ticks : int
        Arbitrary: ticks per level.
    period_s : float or None
        One period or pass [s] (None: not periodic).
    summary : str
        One line describing the wave in units.
    info : dict
        What the user asked, in units, for ``--json``.
    """

    kind: str
    offset_q15: int = 0
    amplitude_q15: int = 0
    f_hz: float = 0.0
    f_end_hz: float | None = None
    duration_s: float | None = None
    cycles: int = 0
    tones: list = field(default_factory=list)
    levels_q15: list = field(default_factory=list)
    durations_ticks: list = field(default_factory=list)
    hold_ticks: int = 1
    period_s: float | None = None
    summary: str = ""
    info: dict = field(default_factory=dict)

    def load(self, ctl) -> None:
        """Write the wave to the controller (not started)."""
        ctl.configure_wave(self.kind, offset_q15=self.offset_q15, amplitude_q15=self.amplitude_q15,
                           f_hz=self.f_hz, f_end_hz=self.f_end_hz, duration_s=self.duration_s,
                           cycles=self.cycles, tones=self.tones or None,
                           levels_q15=self.levels_q15 or None, durations_ticks=self.durations_ticks or None,
                           hold_ticks=self.hold_ticks)

    def play_s(self) -> float | None:
        """How long the wave plays [s], None when endless."""
        if self.kind == "chirp":
            return self.duration_s
        if self.cycles and self.period_s:
            return self.cycles * self.period_s
        return None


class _Range:
    """The unit the user speaks (um of position or V of drive) against the controller's q15."""

    def __init__(self, scale, volts: bool):
        self.volts = volts
        self.unit = "V" if volts else "um"
        if volts:
            self.lo, self.hi = scale.drive_min_v, scale.drive_max_v
        else:
            self.lo, self.hi = scale.position_min_um, scale.position_max_um
        self.mid, self.half = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)

    def q15(self, x: float) -> int:
        """A value [unit] as q15 of the range (rounded, saturated)."""
        return int(min(32767, max(-32768, math.floor((x - self.mid) / self.half * 32768 + 0.5))))

    def q15_span(self, a: float) -> int:
        """An amplitude [unit] as q15 of the half range (rounded)."""
        return int(math.floor(a / self.half * 32768 + 0.5))

    def check_inside(self, lo: float, hi: float, what: str) -> None:
        tol = 1e-9 * self.half
        if lo < self.lo - tol or hi > self.hi + tol:
            raise CliError(f"{what} spans {lo:g}..{hi:g} {self.unit}, outside the controller's range "
                           f"{self.lo:g}..{self.hi:g} {self.unit}")


def _positive(name: str, v: float | None) -> float:
    if v is None or not math.isfinite(v) or v <= 0:
        raise CliError(f"{name} must be > 0 (got {v if v is not None else 'none'})")
    return float(v)


def _frequency(name: str, f: float | None, tick_hz: float) -> float:
    nyq = 0.5 * tick_hz
    if f is None or not math.isfinite(f) or f <= 0:
        raise CliError(f"{name} must be > 0 Hz (got {f if f is not None else 'none'})")
    if f >= nyq:
        raise CliError(f"{name} {f:g} Hz is not below the Nyquist frequency {nyq:g} Hz "
                       f"(the controller ticks at {tick_hz:g} Hz)")
    return float(f)


def parse_tones(text: str, tick_hz: float) -> list[tuple[float, float, float]]:
    """``"10:0.5,37:0.3:90"`` -> ``[(10.0, 0.5, 0.0), (37.0, 0.3, pi/2)]``.

    Each tone is ``FREQ:AMPLITUDE[:PHASE]``: frequency [Hz] in (0, Nyquist),
    amplitude > 0 [um, or V with --volts], start phase [deg] (default 0).
    At most :data:`MAX_TONES` tones.
    """
    tones = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        parts = item.split(":")
        if len(parts) not in (2, 3):
            raise CliError(f"--tones: {item!r} is not FREQ:AMPLITUDE[:PHASE_DEG] (e.g. 10:0.5,37:0.3)")
        try:
            f, a = float(parts[0]), float(parts[1])
            ph = float(parts[2]) if len(parts) == 3 else 0.0
        except ValueError:
            raise CliError(f"--tones: {item!r}: not numbers (want FREQ:AMPLITUDE[:PHASE_DEG])") from None
        _frequency(f"--tones: frequency of {item!r}", f, tick_hz)
        _positive(f"--tones: amplitude of {item!r}", a)
        if not math.isfinite(ph):
            raise CliError(f"--tones: phase of {item!r} must be a finite number of degrees")
        tones.append((f, a, math.radians(ph)))
    if not tones:
        raise CliError("--tones names no tone (want FREQ:AMPLITUDE[:PHASE_DEG],...)")
    if len(tones) > MAX_TONES:
        raise CliError(f"--tones: {len(tones)} tones; the wave generator plays at most {MAX_TONES}")
    return tones


def read_wave_file(path: str) -> dict:
    """Columns ``t`` and ``reference``, ``y``, ``u`` (those present) of a wave file, as float arrays.

    The recording CSV format (``docs/recordings.md``: ``# key: value`` lines,
    a header, comma-separated rows); other columns are ignored. Refuses, in
    one line naming the file and line: no ``t``, a field that is not a
    finite number, fewer than 2 rows, ``t`` not strictly increasing.
    """
    import numpy as np

    try:
        with open(path, encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise CliError(f"{path}: cannot read: {exc.strerror or exc}") from None
    rows = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise CliError(f"{path}: no header line")
    names = [n.strip() for n in rows[0][1].split(",")]
    if "t" not in names:
        raise CliError(f"{path}: line {rows[0][0]}: no column t (want t and reference, y or u)")
    want = {n: names.index(n) for n in ("t", "reference", "y", "u") if n in names}
    data = {n: [] for n in want}
    for lineno, ln in rows[1:]:
        fields = ln.split(",")
        if len(fields) != len(names):
            raise CliError(f"{path}: line {lineno}: {len(fields)} fields, the header has {len(names)}")
        for n, k in want.items():
            try:
                x = float(fields[k])
            except ValueError:
                x = float("nan")
            if not math.isfinite(x):
                raise CliError(f"{path}: line {lineno}: column {k + 1} '{n}': {fields[k].strip()!r} "
                               "is not a finite number")
            data[n].append(x)
    if len(data["t"]) < 2:
        raise CliError(f"{path}: fewer than 2 rows")
    out = {n: np.asarray(v, dtype=np.float64) for n, v in data.items()}
    bad = np.flatnonzero(np.diff(out["t"]) <= 0)
    if bad.size:
        raise CliError(f"{path}: line {rows[bad[0] + 2][0]}: time not increasing")
    return out


def resample_file(path: str, hold_s: float | None, tick_hz: float, max_levels: int, *,
                  volts: bool, steps: bool = False) -> dict:
    """Read a wave file and turn it into the generator's levels.

    The file is a recording CSV (``docs/recordings.md``) with ``t`` [s] and
    one value column: ``reference`` or ``y`` [um] (a position wave), or
    ``u`` [V] (a drive wave; picked with ``volts`` or when it is the only
    one). ``arbitrary``: the values are sampled (linear interpolation) every
    hold, ``hold_s`` [s] rounded to whole ticks, default the file's median
    step; a file of duration D (last ``t`` minus first plus one step) gives
    ``round(D / hold)`` levels. ``steps``: each row is a level held until
    the next row's time (the last for the median step).

    Returns
    -------
    dict
        ``values`` (ndarray, the levels in the file's unit), ``unit``,
        ``column``, ``hold_ticks`` (arbitrary), ``durations_ticks`` (steps),
        ``period_s``.
    """
    import numpy as np

    cols = read_wave_file(path)
    if volts or ("u" in cols and "reference" not in cols and "y" not in cols):
        if "u" not in cols:
            raise CliError(f"{path}: no column u [V] (a drive wave with --volts needs t,u)")
        column = "u"
    elif "reference" in cols:
        column = "reference"
    elif "y" in cols:
        column = "y"
    else:
        raise CliError(f"{path}: no value column: want t and one of reference or y [um], or u [V]")
    t, v = cols["t"], cols[column]
    dt = float(np.median(np.diff(t)))
    tick_s = 1.0 / tick_hz
    out = {"column": column, "unit": "V" if column == "u" else "um"}
    if steps:
        edges = np.append(t - t[0], t[-1] - t[0] + dt)
        ticks = np.round(np.diff(edges) * tick_hz).astype(np.int64)
        if ticks.min() < 1:
            raise CliError(f"{path}: a step shorter than one tick ({tick_s:g} s)")
        if len(v) > max_levels:
            raise CliError(f"{path}: {len(v)} steps; the wave generator holds {max_levels} levels: "
                           f"keep at most {max_levels} rows")
        out.update(values=v, durations_ticks=[int(k) for k in ticks], period_s=float(ticks.sum()) * tick_s)
        return out
    if hold_s is None:
        hold_ticks = max(1, int(round(dt * tick_hz)))
        how = "the file's step"
    else:
        _positive("--hold", hold_s)
        hold_ticks = int(round(hold_s * tick_hz))
        if hold_ticks < 1:
            raise CliError(f"--hold {hold_s:g} s is shorter than one tick ({tick_s:g} s)")
        if hold_ticks >= 2**32:
            raise CliError(f"--hold {hold_s:g} s is longer than the generator counts (2^32 ticks)")
        how = "--hold"
    hold = hold_ticks * tick_s
    dur = float(t[-1] - t[0]) + dt
    n = max(1, int(round(dur / hold)))
    if n > max_levels:
        short = max_levels * hold
        coarser = dur / max_levels
        raise CliError(f"{path}: {dur:g} s at a hold of {hold:g} s ({hold_ticks} ticks, {how}) needs {n} "
                       f"levels; the wave generator holds {max_levels}: shorten the file to {short:g} s "
                       f"or pass --hold {math.ceil(coarser * tick_hz) * tick_s:g} (or longer) "
                       "to resample it coarser")
    values = np.interp(t[0] + np.arange(n) * hold, t, v)
    out.update(values=values, hold_ticks=hold_ticks, period_s=n * hold, hold_how=how)
    return out


def plan_wave(args, tick_hz: float, scale, max_levels: int) -> WaveSpec:
    """Check the options of ``wave`` and turn them into a :class:`WaveSpec` (nothing is written)."""
    kind = args.kind
    if args.tones is not None:
        if kind not in (None, "multisine"):
            raise CliError(f"--tones makes a multisine, not a {kind}")
        kind = "multisine"
    if args.file is not None:
        if kind not in (None, "arbitrary", "steps"):
            raise CliError(f"--file plays an arbitrary or steps wave, not a {kind}")
        kind = kind or "arbitrary"
    if kind is None:
        raise CliError(f"say which wave: --kind {'|'.join(KINDS)} (or --tones, --file), or --stop")
    if args.cycles < 0:
        raise CliError(f"--cycles must be >= 0 (0 = endless; got {args.cycles})")
    if args.cycles >= 2**32:
        raise CliError(f"--cycles must be < 2^32 (got {args.cycles})")
    rng = _Range(scale, args.volts)
    u = rng.unit
    cyc = f"{args.cycles} cycle(s)" if args.cycles else "endless"

    if kind in ("arbitrary", "steps"):
        if args.file is None:
            raise CliError(f"a {kind} wave needs --file X.csv (t and reference, y or u)")
        if args.amplitude is not None or args.offset is not None:
            raise CliError(f"--amplitude and --offset do not apply to a {kind} wave: the file gives the values")
        if kind == "steps" and args.hold is not None:
            raise CliError("--hold applies to an arbitrary wave; a steps wave holds each row until the next")
        f = resample_file(args.file, args.hold, tick_hz, max_levels, volts=args.volts, steps=kind == "steps")
        frng = _Range(scale, f["unit"] == "V")
        v = f["values"]
        lo, hi = float(v.min()), float(v.max())
        frng.check_inside(lo, hi, f"{args.file} column {f['column']}")
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        amp_q = min(32767, frng.q15_span(half))
        if amp_q < 1:
            raise CliError(f"{args.file}: column {f['column']} is constant ({lo:g} {f['unit']}): "
                           "amplitude 0 is no wave (use the setpoint)")
        levels = [int(min(32767, max(-32768, math.floor((x - mid) / half * 32767 + 0.5)))) for x in v]
        what = (f"{len(levels)} levels held {f['hold_ticks']} ticks ({f['hold_ticks'] / tick_hz:g} s, "
                f"{f['hold_how']})" if kind == "arbitrary" else f"{len(levels)} steps")
        return WaveSpec(kind, offset_q15=frng.q15(mid), amplitude_q15=amp_q, cycles=args.cycles,
                        levels_q15=levels, hold_ticks=f.get("hold_ticks", 1),
                        durations_ticks=f.get("durations_ticks", []), period_s=f["period_s"],
                        summary=f"{kind} from {args.file} ({f['column']}, {lo:g}..{hi:g} {f['unit']}): "
                                f"{what}, {f['period_s']:g} s per pass, {cyc}",
                        info={"file": args.file, "column": f["column"], "unit": f["unit"],
                              "levels": len(levels), "hold_ticks": f.get("hold_ticks"),
                              "period_s": f["period_s"]})
    if args.file is not None or args.hold is not None:
        raise CliError(f"--file and --hold apply to arbitrary and steps waves, not a {kind}")

    off = rng.mid if args.offset is None else args.offset
    if not math.isfinite(off):
        raise CliError("--offset must be a finite number")
    if kind == "multisine":
        if args.tones is None:
            raise CliError("a multisine needs --tones FREQ:AMPLITUDE[:PHASE_DEG],... (e.g. 10:0.5,37:0.3)")
        if args.amplitude is not None:
            raise CliError("--amplitude does not apply to a multisine: each tone has its own (--tones)")
        if args.cycles:
            raise CliError("--cycles does not apply to a multisine: the generator plays it until stopped")
        tones = parse_tones(args.tones, tick_hz)
        total = sum(a for _, a, _ in tones)
        rng.check_inside(off - total, off + total, f"the multisine (offset {off:g} {u} +- the tones' sum {total:g} {u})")
        tq = []
        for f, a, ph in tones:
            aq = rng.q15_span(a)
            if aq < 1:
                raise CliError(f"--tones: amplitude {a:g} {u} at {f:g} Hz is below the controller's "
                               f"resolution ({rng.half / 32768:.3g} {u})")
            tq.append((aq, f, ph))
        lowest = min(f for f, _, _ in tones)
        return WaveSpec(kind, offset_q15=rng.q15(off), tones=tq, period_s=1.0 / lowest,
                        summary=f"multisine of {len(tones)} tone(s) "
                                + ", ".join(f"{f:g} Hz {a:g} {u}" for f, a, _ in tones)
                                + f" about {off:g} {u}, endless",
                        info={"tones": [{"freq_hz": f, "amplitude": a, "phase_deg": math.degrees(p)}
                                        for f, a, p in tones], "offset": off, "unit": u})

    amp = _positive("--amplitude", args.amplitude)
    rng.check_inside(off - amp, off + amp, f"offset {off:g} {u} +- amplitude {amp:g} {u}")
    amp_q = rng.q15_span(amp)
    if amp_q > 32767:
        raise CliError(f"--amplitude {amp:g} {u} exceeds the controller's half range {rng.half:g} {u}")
    if amp_q < 1:
        raise CliError(f"--amplitude {amp:g} {u} is below the controller's resolution ({rng.half / 32768:.3g} {u})")
    f0 = _frequency("--freq", args.freq, tick_hz)
    info = {"offset": off, "amplitude": amp, "unit": u, "freq_hz": f0}
    if kind == "chirp":
        if args.freq_end is None:
            raise CliError("a chirp needs an end: --freq-end HZ (and --duration S)")
        f1 = _frequency("--freq-end", args.freq_end, tick_hz)
        if f1 <= f0:
            raise CliError(f"a chirp sweeps upward: --freq-end ({f1:g} Hz) must be above --freq ({f0:g} Hz)")
        dur = _positive("--duration (the chirp's length, s)", args.duration)
        # the generator adds a whole word per tick: the sweep must gain at least one per tick
        if (f1 - f0) / tick_hz * 2.0**32 / (dur * tick_hz) < 1.0:
            raise CliError(f"a chirp from {f0:g} to {f1:g} Hz in {dur:g} s is slower than the generator's "
                           "finest sweep rate: a shorter --duration or a wider band")
        if args.cycles:
            raise CliError("--cycles does not apply to a chirp: it ends at --freq-end")
        info.update(freq_end_hz=f1, chirp_s=dur)
        return WaveSpec(kind, offset_q15=rng.q15(off), amplitude_q15=amp_q, f_hz=f0, f_end_hz=f1,
                        duration_s=dur, summary=f"chirp {f0:g}..{f1:g} Hz in {dur:g} s, amplitude {amp:g} {u} "
                                                f"about {off:g} {u}", info=info)
    if args.freq_end is not None:
        raise CliError(f"--freq-end applies to a chirp, not a {kind}")
    return WaveSpec(kind, offset_q15=rng.q15(off), amplitude_q15=amp_q, f_hz=f0, cycles=args.cycles,
                    period_s=1.0 / f0, info=info,
                    summary=f"{kind} {f0:g} Hz, amplitude {amp:g} {u} about {off:g} {u}, {cyc}")


def add_parser(sub) -> None:
    w = sub.add_parser("wave", help="load and start the wave generator (optionally recording the run), or stop it",
                       description="Load and start the wave generator. Amplitudes and offsets are um of "
                                   "position, or drive V with --volts. Nonsense values are refused before "
                                   "anything is written. --stop alone stops it.")
    add_port(w)
    w.add_argument("--stop", action="store_true", help="stop the wave generator (takes no wave options)")
    w.add_argument("--saved", action="store_true",
                   help="start the wave the controller holds (loaded at boot from its flash record, with its "
                        "learned feedforward) without writing a new one; takes --mode and --record")
    w.add_argument("--kind", choices=KINDS, help="the wave (--tones implies multisine, --file arbitrary)")
    w.add_argument("--volts", action="store_true", help="amplitude and offset are drive [V] (open loop, no table)")
    w.add_argument("--amplitude", type=float, help="peak [um, or V with --volts], > 0")
    w.add_argument("--offset", type=float, help="centre [um, or V] (default: mid-range)")
    w.add_argument("--freq", type=float, default=1.0, help="[Hz], in (0, Nyquist); chirp start (default 1)")
    w.add_argument("--freq-end", type=float, help="chirp end [Hz]")
    w.add_argument("--tones", metavar="F:A[:PH],...",
                   help="multisine: up to 8 tones of frequency [Hz] : amplitude [um, or V] : start phase "
                        "[deg, default 0], e.g. 10:0.5,37:0.3")
    w.add_argument("--file", metavar="X.csv",
                   help="arbitrary (or --kind steps) wave: t [s] and reference or y [um], or u [V]")
    w.add_argument("--hold", type=float, metavar="S",
                   help="arbitrary: seconds per level, rounded to ticks (default the file's step)")
    w.add_argument("--cycles", type=int, default=0, help="periods or passes to play, 0 = endless (default)")
    w.add_argument("--mode", choices=["idle", "open_loop", "feedforward", "ff_feedback", "feedback", "direct"],
                   help="set the control mode first (disarms and re-arms)")
    w.add_argument("--record", metavar="OUT.csv", help="record the run from the wave's first sample")
    w.add_argument("--learn", type=int, metavar="N",
                   help="periodic waves: learn a feedforward correction over N trials (1..50) before starting "
                        "(armed in ff_feedback or feedback); piezoctl params save keeps it")
    w.add_argument("--learn-cut", type=float, metavar="HZ",
                   help="the band the learning corrects [Hz] (default: 2 x the notch frequency)")
    add_capture_options(w, duration_required=False)
    add_output(w)
    w.set_defaults(func=run_wave)


_WAVE_OPTIONS = ("kind", "amplitude", "offset", "freq_end", "tones", "file", "hold", "mode", "record",
                 "duration", "plot", "learn", "learn_cut")
LEARN_MAX_TRIALS = 50
LEARN_F_CUT = 2.0   # default band: a multiple of the notch frequency (calibrate's ILC_F_CUT)


def run_wave(args) -> int:
    from .. import interface
    from ..device import connect

    if args.saved:
        return _run_saved(args)
    if args.stop:
        given = [o for o in _WAVE_OPTIONS if getattr(args, o) is not None] + \
                [o for o in ("volts", "stream") if getattr(args, o)] + (["cycles"] if args.cycles else [])
        if given:
            raise CliError(f"--stop takes no wave options (got --{', --'.join(g.replace('_', '-') for g in given)})")
        ctl = connect(args.port)
        ctl.command("stop_wave")
        emit(args, {"port": args.port, "stopped": True}, f"wave stopped on {args.port}")
        return 0
    if args.record is None:
        extra = [o for o, on in (("--plot", args.plot), ("--stream", args.stream),
                                 ("--decimation", str(args.decimation) != "auto"),
                                 ("--signals", args.signals != "ref,y,u"),
                                 ("--duration", args.duration is not None and args.kind != "chirp")) if on]
        if extra:
            raise CliError(f"{', '.join(extra)} appl{'ies' if len(extra) == 1 else 'y'} to --record"
                           + (" (a chirp's length is --duration)" if "--duration" in extra else ""))
    if args.learn is not None and not 1 <= args.learn <= LEARN_MAX_TRIALS:
        raise CliError(f"--learn {args.learn}: give 1..{LEARN_MAX_TRIALS} trials")
    if args.learn_cut is not None and args.learn is None:
        raise CliError("--learn-cut applies to --learn")
    sigs, ctl = _capture_checked(args)
    tick = float(ctl.identity.tick_hz)
    spec = plan_wave(args, tick, ctl.scale, interface.HOLDING_REGISTERS["wave_levels"][2])
    f_cut = _learn_plan(args, spec, ctl, tick) if args.learn is not None else None
    rec_s = None
    if args.record:
        rec_s = args.duration if args.duration is not None else (spec.play_s() or 1.0)
        # checked before anything is written: a capture that cannot fit refuses here
        from .record import choose_decimation
        choose_decimation(rec_s, len(sigs), tick, ctl.identity.rec_capacity, args.decimation, args.stream)
    progress(args, spec.summary)
    if args.mode:
        ctl.arm(False)
        ctl.set_mode(args.mode)
        ctl.arm(True)
    spec.load(ctl)
    result = {"port": args.port, "kind": spec.kind, "summary": spec.summary, "cycles": spec.cycles,
              "play_s": spec.play_s(), **spec.info}
    lines = []
    if args.learn is not None:
        result["learned"] = _learn(args, spec, ctl, f_cut)
        spec.load(ctl)   # the trials changed its cycles
        lr = result["learned"]
        lines.append(f"learned feedforward: {lr['first_rms_um'] * 1e3:.1f} -> {lr['best_rms_um'] * 1e3:.1f} nm RMS "
                     f"over one period in {lr['trials']} trials ({lr['refused']} refused), {lr['n_entries']} "
                     f"entries, learned below {lr['f_cut_hz']:.0f} Hz; played with the wave "
                     "(piezoctl params save keeps both)")
    lines.insert(0, f"wave {spec.summary}: started on {args.port}")
    _start(args, ctl, sigs, rec_s, result, lines)
    # the controller refuses a wave it cannot play by not starting it
    if spec.play_s() is None and not ctl.status()["wave_running"]:
        raise ControllerRefused("the controller did not start the wave (wave_running 0)")
    result["running"] = bool(ctl.status()["wave_running"])
    emit(args, result, lines)
    return 0


def _capture_checked(args):
    """The signals to record and the connected controller, once the output files are known writable
    (checked before anything is written to the controller)."""
    from ..device import connect
    sigs = parse_signals(args.signals)
    check_writable(args.record, "--record")
    check_writable(args.plot, "--plot", PLOT_SUFFIXES)
    return sigs, connect(args.port)


def _start(args, ctl, sigs: list, rec_s, result: dict, lines: list) -> None:
    """Start the loaded wave, recording ``rec_s`` seconds of it with ``--record``;
    adds ``record`` to ``result`` and its lines to ``lines``."""
    if not args.record:
        ctl.command("start_wave")
        return
    res = record(args, ctl, sigs, rec_s, args.record, start_wave=True)
    result["record"] = res
    lines.append(f"{res['out']}: {res['frames']} samples of {', '.join(sigs)} at {res['sample_rate_hz']:g} Hz "
                 f"(decimation {res['decimation']}{', chosen' if res['decimation_chosen'] else ''})")
    if res["stream"]:
        lines.append(f"lost frames: {res['lost_frames']} of {res['frames_wanted']}")
    if res["plot"]:
        lines.append(f"plot: {res['plot']}")


def _learn_plan(args, spec: WaveSpec, ctl, tick_hz: float) -> float:
    """Check that ``--learn`` can run on this wave and controller; returns the band [Hz].
    Refuses (CliError, nothing written) a wave that does not repeat, or a
    controller not armed in a mode with feedback."""
    from .. import interface
    if spec.period_s is None or spec.kind == "chirp":
        raise CliError("--learn needs a periodic wave (sine, triangle, multisine, steps, arbitrary): "
                       "a chirp does not repeat")
    if spec.kind == "multisine":
        lowest = 1.0 / spec.period_s
        if any(abs(f / lowest - round(f / lowest)) > 1e-6 for _, f, _ in spec.tones):
            raise CliError("--learn: the tones must be multiples of the lowest one (the correction repeats "
                           "with one period)")
    st = ctl.status()
    mode = args.mode or {v: k for k, v in interface.ENUMS["mode"].items()}.get(st["mode"], "")
    if mode not in ("ff_feedback", "feedback") or not (st["armed"] or args.mode):
        raise CliError(f"--learn learns through the closed loop: arm the unit in ff_feedback or feedback "
                       f"(now {mode or st['mode']}, {'armed' if st['armed'] else 'disarmed'}; --mode sets it)")
    if args.learn_cut is not None:
        if not 0.0 < args.learn_cut < tick_hz / 2:
            raise CliError(f"--learn-cut {args.learn_cut:g} Hz: want (0, {tick_hz / 2:g}) Hz")
        return float(args.learn_cut)
    p = ctl.read_params()
    if not p.get("notch_on"):
        raise CliError("--learn needs --learn-cut HZ: the controller has no notch to take the stage's "
                       "resonance from (the band learned is 2 x the notch frequency by default)")
    b0, b1 = p["notch_b0_q24"] / 2.0**24, p["notch_b1_q24"] / 2.0**24
    c = -b1 / (2.0 * b0) if b0 else 2.0
    if not -1.0 <= c <= 1.0:
        raise CliError("--learn needs --learn-cut HZ: the controller's notch has no frequency to read")
    return min(LEARN_F_CUT * math.acos(c) * tick_hz / (2.0 * math.pi), 0.45 * tick_hz)


def _learn(args, spec: WaveSpec, ctl, f_cut: float) -> dict:
    """Learn the loaded wave's feedforward (``calibrate/ilc.py``); it is left committed."""
    from ..calibrate import ilc
    f0 = 1.0 / spec.period_s
    preview = ctl.read_params().get("preview_ticks", 0)
    periods = 1 if f0 < 10 else max(5, int(round(0.1 * f0)))
    progress(args, f"learning the feedforward: {args.learn} trials of {periods} period(s) ...")
    res = ilc.learn_on_controller(ctl, f0, preview_ticks=int(preview), f_cut_hz=f_cut, iterations=args.learn,
                                  periods=periods, say=lambda m: progress(args, m))
    return {"trials": len(res["history"]), "refused": res["refused"], "first_rms_um": res["first_rms_um"],
            "best_rms_um": res["best_rms_um"], "n_entries": res["n_entries"], "f_cut_hz": res["f_cut_hz"],
            "clipped": res["clipped"], "history_rms_um": [h["rms_um"] for h in res["history"]]}


_DEFINING = ("kind", "amplitude", "offset", "freq_end", "tones", "file", "hold")


def _run_saved(args) -> int:
    """``--saved``: start the wave the controller holds (refused when it holds none)."""
    from .. import interface
    from ..device import PARAMS_WAVE_NAMES

    given = [o for o in _DEFINING + ("learn", "learn_cut") if getattr(args, o) is not None] + \
        (["volts"] if args.volts else []) + (["cycles"] if args.cycles else []) + (["stop"] if args.stop else [])
    if given:
        raise CliError(f"--saved starts the wave the controller holds: it takes no "
                       f"--{', --'.join(g.replace('_', '-') for g in given)}")
    if args.record is not None and args.duration is None:
        raise CliError("--saved --record needs --duration (the saved wave's length is not known here)")
    sigs, ctl = _capture_checked(args)
    st = ctl.status()
    kind = ctl.client.read_holding(interface.HOLDING_REGISTERS["wave_kind"][0])[0]
    if kind == 0:
        raise ControllerRefused("the controller holds no wave (wave_kind off): nothing to start; "
                                "piezoctl params save keeps a wave over a restart")
    if args.mode:
        ctl.arm(False)
        ctl.set_mode(args.mode)
        ctl.arm(True)
    ctl.write("ref_source", 1)
    names = {v: k for k, v in interface.ENUMS["wave_kind"].items()}
    result = {"port": args.port, "kind": names.get(kind, str(kind)), "saved": True,
              "learned_ff_entries": st["wave_ff_n_live"],
              "params_wave": PARAMS_WAVE_NAMES.get(st["params_wave"], str(st["params_wave"]))}
    lines = [f"saved {result['kind']} wave started on {args.port}"
             + (f", with its learned feedforward ({st['wave_ff_n_live']} entries)" if st["wave_ff_n_live"] else "")]
    _start(args, ctl, sigs, args.duration, result, lines)
    result["running"] = bool(ctl.status()["wave_running"])
    emit(args, result, lines)
    return 0
