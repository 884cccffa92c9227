"""Two-axis stages: calibrate the second axis, then the cross-axis coupling.

After each axis' own hysteresis calibration (:func:`piezoctl.calibrate.pipeline.calibrate`,
axis 2 into ``DIR/axis2/``), for each receiving axis i and the other axis j:

1. identification: axis i held in DIRECT mode at 3 drive levels (its
   positions); at each, after 1 s of settling, axis j (DIRECT) plays a chirp
   1 -> 60 Hz over 3 s, +-0.8 of its half drive range around mid drive (wider than
   the evaluation's drive: the polynomial must not extrapolate), and axis i's
   recorder keeps y and u2 (the other axis' drive as axis i's controller sees
   it); y minus its straight-line trend (axis i's creep) is the coupling;
2. the coupling map u2 -> y at position x (axis i's mean position) is fitted
   with the hammerstein kind at the firmware kernel's settings
   (:data:`piezoctl.tables.coupling.KERNEL_SETTINGS`), the pairs aligned as
   the controller acts on them (input of tick k, output seen from tick k + 2);
3. the table (output: the coupling divided by axis i's static gain, the slope
   of its calibrated straight line) is uploaded, read back, committed and
   confirmed through ``coupling_table_crc``;
4. evaluation: both axes in their compensated mode (their tables, feedback;
   axis j's shaper; axis i holds a constant, so its shaper is off and would
   only keep the learned correction from its own mode, where the coupling
   rings it), axis i holding mid stroke while axis j tracks a triangle over
   60 % of its stroke at 10 and at 50 Hz; axis i's RMS error with the
   compensation bypassed (``xcouple_bypass`` = 1: uncompensated), applied,
   and applied with axis i's learned feedforward: axis i's wave (a constant
   at mid stroke, at axis j's frequency) starts at the tick axis j's drive
   rises through its middle (``start_wave_on_trigger``, the recorder's
   trigger on ``u2``, its level measured again for every record), so its
   correction (``ilc.py``, learned over :data:`ILC_TRIALS` trials while axis j
   keeps running, up to :data:`ILC_F_CUT_HZ`, through axis i's loop measured in
   place with a flat multisine played as the correction) is in step with the
   coupling in every trial.

``summary.json`` (axis 1's) gains ``coupling``: per axis (``"1"``, ``"2"``:
the receiving axis) ``rmse_uncompensated_um``, ``rmse_compensated_um`` and
``reduction`` at 10 Hz, ``by_frequency`` for both frequencies (also
``rmse_table_only_um``; the part of each error that repeats with the other
axis' period, noise-corrected (:func:`periodic_rms`), as
``rmse_periodic_uncompensated_um``, ``rmse_periodic_table_only_um``,
``rmse_periodic_um`` (compensated) and ``reduction_periodic``, with
``noise_rms_um`` what does not repeat; ``periods`` measured; ``valid``:
false when an axis faulted while they were measured; ``faults_cleared``,
``attempts`` and the learning's trials), the table CRC and the fit; and
``axes``: where axis 2's own calibration is. The sensor noise floors the
RMS figures (2 nm on the SIL stages); the periodic ones measure the coupling.
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import numpy as np

from ..device import DeviceError
from ..errors import CliError
from . import ilc
from .excitation import load_triangle, settle_periods
from ..ident import hammerstein as ham
from ..tables.coupling import KERNEL_SETTINGS, coupling_table
from ..transport import open_port

__all__ = ["other_axis_port", "identify_coupling", "flash_coupling", "evaluate_coupling", "calibrate_two_axis"]

LEAD = 2                       # ticks: a drive change at tick k shows from the sample of tick k + 2
LEVELS = (0.3, 0.5, 0.7)       # axis i's drive levels (fractions of the range)
CHIRP_S = 3.0
SETTLE_S = 1.0
EVAL_FREQS = (10.0, 50.0)     # the other axis' triangle [Hz]
ILC_TRIALS = 15               # the held axis' learning (at its floor after 7 trials at 10 Hz, 9 at 50 Hz)
OTHER_STROKE = 0.6            # the other axis' triangle over this fraction of its stroke (0.8, with its shaper:
                              # the coupling table made 50 Hz worse, 62.8 -> 100.8 nm: beyond what it was fitted on)
ILC_F_CUT_HZ = 1500.0         # the held axis' learning band [Hz] (3 x the resonance until 2026-11-26: the
                              # coupling's lines near the 620 Hz mode were left, 9.7 of the 10.3 nm at 50 Hz)
ILC_GAIN_MAX = 100.0          # largest |1 / T| of its learning filter (the loop falls to 0.1 near its antiresonance
                              # at 550 Hz, to 0.05 above 1 kHz)
TRIAL_S = 1.0                 # a learning trial's periods last this long [s], at least 5 (0.1 until 2026-11-26; 0.5 s left
                              # 0.35-0.47 nm periodic at 10 Hz, 1 s 0.17-0.27 nm)
STILL_SETTLE_S = 0.25         # the held axis' records start this long after its wave [s] (0.05 until 2026-11-26:
                              # 2.6-4 nm of the start's ringing left in the 50 Hz trials' first period)
PROBE_RMS_UM = 0.1            # the loop measurement's multisine [um RMS]
PROBE_S = 2.0                 # ... recorded over this long [s] (as much as the recorder holds)
EVAL_PERIODS = 20             # periods of the other axis' triangle each figure is measured over (the
                              # periodic figures' noise: 2 nm / sqrt(20) before the correction)


def _log(args, text: str) -> None:
    """A progress line on stderr (silenced by the command's --quiet and --json)."""
    if args is None:
        print(f"[coupling] {text}", file=sys.stderr, flush=True)
    else:
        from ..commands._options import progress
        progress(args, f"coupling: {text}")


def other_axis_port(port: str, axis: int = 2) -> tuple[str, int]:
    """(port, unit id) of axis ``axis`` (1-based) of the controller at ``port``.

    TCP: axis i is served on port PORT + i - 1 (unit id i); RTU and USB: the
    same line, unit id i.
    """
    if port.startswith("tcp:"):
        head, _, p = port.rpartition(":")
        return f"{head}:{int(p) + axis - 1}", axis
    return port, axis


def connect_axis(port: str, axis: int = 2):
    from ..device import Controller
    p, unit = other_axis_port(port, axis)
    return Controller(open_port(p, unit=unit, timeout=1.0))


def _hold_direct(ctl, q15: int) -> None:
    """DIRECT mode holding drive ``q15``, reached by a ramp (a drive step rings a
    low first mode past the sensor's range: the sensor fault), with no input
    shaper, preview, dynamics inverse or learned feedforward: they act on the
    reference in DIRECT mode too, and an axis
    just calibrated has its own (the 140 Hz stage's ZVD shaper took the chirp's
    content near the mode out of the identification: the first pair's tables
    left 8.3 nm at 10 Hz where the second's left 4.2)."""
    from .pipeline import _park, drive_path_raw
    st = ctl.status()
    if not (st["armed"] and st["mode"] == 5):
        _park(ctl, -32768)
        ctl.command("stop_wave")
        drive_path_raw(ctl)
        ctl.set_mode("direct")
        ctl.write("setpoint_q15", -32768)
        ctl.write("ref_source", 0)
        _arm(ctl)
        q0 = -32768
    else:
        q0 = st["reference_q15"]
        ctl.write("setpoint_q15", q0)
        ctl.write("ref_source", 0)
    for k in range(1, 41):
        ctl.write("setpoint_q15", int(round(q0 + (q15 - q0) * k / 40)))
        time.sleep(0.3 / 40)


def identify_coupling(ci, cj) -> dict:
    """Records of the coupling into axis i (controller ``ci``) from axis j (``cj``).

    Returns ``{"u": [...], "x": [...], "y": [...]}`` (aligned, physical units).
    """
    tick = ci.identity.tick_hz
    frames = int(CHIRP_S * tick) + int(0.2 * tick)
    us, xs, ys = [], [], []
    for lv in LEVELS:
        _hold_direct(ci, int(round((2 * lv - 1) * 32767)))
        _hold_direct(cj, 0)
        time.sleep(SETTLE_S)
        cj.configure_wave("chirp", offset_q15=0, amplitude_q15=int(0.8 * 32767), f_hz=1.0, f_end_hz=60.0,
                          duration_s=CHIRP_S)
        ci.configure_recorder(["y", "u2"], trigger="immediate")
        ci.command("arm_recorder")
        cj.command("start_wave")
        try:
            ci.wait_recorder(frames, 3 * CHIRP_S + 10)   # in the controller's time (device.py)
        except DeviceError as exc:
            cj.command("stop_wave")
            raise CliError(f"coupling identification: {exc}") from None
        data = ci.read_recording(2)[:frames]
        cj.command("stop_wave")
        y = ci.to_physical("y", data[:, 0])
        u2 = cj.scale.drive_from_fs(data[:, 1] / 32768.0)   # the other axis' drive, its own scale
        t = np.arange(y.size) / tick
        trend = np.polyval(np.polyfit(t, y, 1), t)
        us.append(u2[:u2.size - LEAD])
        ys.append((y - trend)[LEAD:])
        xs.append(np.full(u2.size - LEAD, float(np.mean(y))))
    from .pipeline import _park
    for c in (ci, cj):
        _park(c, -32768)
    return {"u": us, "x": xs, "y": ys}


def flash_coupling(ctl, img: bytes, timeout_s: float = 2.0) -> int:
    """Upload, verify, commit a coupling table and wait until it runs (``Controller.flash``, the one way a
    table reaches a controller). Returns its CRC."""
    return int(ctl.flash(img, timeout_s=timeout_s)["crc"])


def _configure_compensated(ctl, comp: dict) -> None:
    from .pipeline import _park
    _park(ctl, -32768 if ctl.status()["mode"] == 5 else ctl.q15_position(comp["stroke"][0]))
    ctl.command("stop_wave")
    ctl.configure_shaper(comp["shaper_ticks"], comp["shaper_q15"], comp["preview_ticks"])
    ctl.configure_feedback(kp=comp["kp"], ki=comp["ki_per_tick"], notch=_notch(comp, ctl.identity.tick_hz))
    ctl.set_mode(comp["mode"])


def _notch(comp: dict, tick_hz: float):
    from .feedback import notch
    return notch(comp["notch_hz"], tick_hz)


def _hold_and_drive(ci, cj, comp_i: dict, comp_j: dict, f: float, bypass: int) -> float:
    """Both axes compensated (axis i's coupling table bypassed or applied), axis i
    holding mid stroke (its wave loaded: a constant there, at the other's
    frequency), axis j tracking a triangle of ``f`` [Hz] over 60 % of its stroke,
    settled; returns axis i's mid position [um]."""
    _configure_compensated(ci, comp_i)
    ci.configure("xcouple_bypass", bypass)
    _configure_compensated(cj, comp_j)
    mid_i = 0.5 * (comp_i["stroke"][0] + comp_i["stroke"][1])
    ci.set_setpoint_um(mid_i)
    ci.configure_wave("triangle", offset_q15=ci.q15_position(mid_i), amplitude_q15=0, f_hz=f)
    _arm(ci)
    lo, hi = comp_j["stroke"]
    load_triangle(cj, f, 0.5 * (lo + hi), 0.5 * OTHER_STROKE * (hi - lo))
    _arm(cj)
    cj.command("start_wave")
    time.sleep(max(1.0, 2.0 / f))              # settle
    return mid_i


def _end_other_wave(cj, n_ticks: int) -> bool:
    """End the other axis' triangle at the end of its current period, back at its
    offset, instead of ``stop_wave`` at whatever phase the host's speed gives.

    ``wave_cycles`` is written while the wave runs: the firmware compares it with
    the periods already played at each period's end, so 1 ends it at the next one.
    The wait is counted in controller ticks (:func:`excitation.wait_wave_end`).
    Until 2026-11-26 the host stopped it at a random phase: a step of up to 60 %
    of the stroke on the other axis, which rings the 140 Hz stage's mode and, through
    the coupling, the held axis; a fault it latched was then counted as one of the
    learning (``compensation_used`` fell back to ``table``). Returns True if the
    wave ended by itself, False if the host had to stop it (it never ran finite).
    """
    from .excitation import wait_wave_end
    cj.write("wave_cycles", 1)
    ended = wait_wave_end(cj, 2 * n_ticks + 1000)
    if not ended:
        cj.command("stop_wave")
    return ended


def periodic_rms(err, n_ticks: int) -> tuple[float, float]:
    """What repeats with the other axis' period, and the noise, in an error record [um].

    The record's whole periods are averaged; the mean's RMS still holds the
    noise divided by the number of periods ``P``, so its square is corrected by
    the noise variance (from the spread across periods) over ``P``: an unbiased
    estimate of the coupling-induced error's RMS, which the sensor noise (2 nm
    RMS on the SIL stages) does not floor.

    Returns
    -------
    periodic : float
        RMS of the error that repeats every period [um] (0 when the noise explains it all).
    noise : float
        RMS of what does not repeat [um].
    """
    e = np.asarray(err, dtype=float)
    p = e.size // n_ticks
    if p < 2:
        raise ValueError(f"a periodic RMS needs at least 2 periods of {n_ticks} samples, not {e.size}")
    e = e[:p * n_ticks].reshape(p, n_ticks)
    var_noise = float(np.mean(np.var(e, axis=0, ddof=1)))
    mean_sq = float(np.mean(e.mean(axis=0) ** 2))
    return float(np.sqrt(max(0.0, mean_sq - var_noise / p))), float(np.sqrt(var_noise))


def _u2_midlevel(ci, n_ticks: int) -> int:
    """The trigger level on the other axis' drive as axis i sees it (q15): halfway
    between the two samples of its rising edge that straddle the middle of its
    range, so the rising crossing marks the same tick of every period.

    (At the middle itself the drive's noise, 3-4 LSB RMS against a 10 Hz
    triangle's 92 LSB a tick, can move the crossing by a tick when a sample lies
    near the level; halfway, 46 LSB from both, it cannot.)"""
    return midlevel(_record_u2(ci, n_ticks), n_ticks)


def _record_u2(ci, n_ticks: int) -> np.ndarray:
    """One period of the other axis' drive as axis i records it (q15 integers)."""
    ci.configure_recorder(["u2"], trigger="immediate")
    ci.command("arm_recorder")
    ci.wait_recorder(n_ticks, 5.0)
    return ci.read_recording(1)[:n_ticks, 0]


def midlevel(u2, n_ticks: int) -> int:
    """The trigger level of one period (at least) of a periodic signal ``u2`` [q15]:
    halfway between the two consecutive samples of its steepest rising step
    through the middle of its range (:func:`_u2_midlevel`)."""
    u = np.asarray(u2, dtype=float)[:n_ticks]
    if u.size < n_ticks or n_ticks < 3:
        raise ValueError(f"need one period of {n_ticks} samples, not {u.size}")
    mid = 0.5 * (u.min() + u.max())
    nxt = np.roll(u, -1)
    k = np.flatnonzero((u < mid) & (nxt >= mid))
    if k.size == 0:
        return int(round(mid))
    k = k[np.argmax(nxt[k] - u[k])]
    return int(round(0.5 * (u[k] + nxt[k])))


def _record_periods(ci, n_ticks: int, periods: int, settle: int, preview: int) -> np.ndarray:
    """Start axis i's wave when the other axis' drive rises through its middle;
    its error [um] over ``periods`` periods after ``settle``, ``periods x n_ticks``,
    each indexed by its wave's sample (recorded frame k is wave sample k - 1 - preview:
    the recorder triggers on the tick before the wave's first; shifted back exactly
    in the period's DFT).

    The middle is measured again for every record (:func:`_u2_midlevel`): the
    other axis' drive drifts as its feedback takes up its creep (a 10 Hz run: by
    215 LSB in 20 s, 2.3 ticks of its triangle's slope), and a level measured
    once started the later trials ticks late against the coupling (the 10 Hz
    learning's 0.3 nm came out 1.3 nm in the evaluation after it)."""
    frames = n_ticks * (periods + settle)
    for _ in range(3):
        level_q15 = _u2_midlevel(ci, n_ticks)
        ci.configure_recorder(["err"], trigger="rising", trigger_signal="u2", level_q15=level_q15)
        # the wave's start first, then the recorder: armed first, it could trigger (every 20 ms at 50 Hz)
        # before the start arrived, and the record ran without the wave or its correction (3 trials of 76)
        ci.command("start_wave_on_trigger")
        ci.command("arm_recorder")
        ci.wait_recorder(frames, frames / ci.identity.tick_hz * 3 + 5)
        running = ci.status()["wave_running"]
        err = ci.to_physical("err", ci.read_recording(1)[:frames, 0])
        ci.command("stop_wave")
        if running:
            break
    else:
        from ..device import DeviceError
        raise DeviceError(f"axis {ci.identity.axis + 1}: its wave did not start on the other axis' drive")
    spec = np.fft.rfft(err[settle * n_ticks:].reshape(periods, n_ticks), axis=1)
    spec *= np.exp(2j * np.pi * np.arange(n_ticks // 2 + 1) * (preview + 1) / n_ticks)
    return np.fft.irfft(spec, n=n_ticks, axis=1)


def _still_trial(ci, n_ticks: int, periods: int, settle: int, preview: int,
                 rms_all: list, periodic_all: list | None = None) -> tuple[np.ndarray, float, float]:
    """:func:`_record_periods` averaged over its periods [um], with the RMS of what
    repeats and its uncertainty (:func:`ilc.periodic_score`: the learning compares
    trials by it; their RMS is mostly the sensor's noise); the RMS over all
    those periods goes to ``rms_all``, and (``periodic_all``) :func:`periodic_rms`'s pair."""
    e_all = _record_periods(ci, n_ticks, periods, settle, preview)
    rms_all.append(float(np.sqrt(np.mean(e_all ** 2))))
    if periodic_all is not None:
        periodic_all.append(periodic_rms(e_all.ravel(), n_ticks))
    score, se = ilc.periodic_score(e_all)
    return e_all.mean(axis=0), score, se


def _still_loop(ci, n_ticks: int, f: float, f_cut: float, settle: int,
                preview: int) -> tuple[np.ndarray, np.ndarray]:
    """Axis i's loop from its learned correction to its error at every harmonic of
    ``f`` [Hz] up to ``f_cut``, and the standard deviation of each value
    (:func:`ilc.loop_from_probe`), measured where the learning acts: the other
    axis tracking its triangle, axis i's wave started in step with it, two
    records of :data:`PROBE_S` each, one without a correction and one with a flat
    multisine (:func:`ilc.probe`, :data:`PROBE_RMS_UM`); their difference is the
    multisine's effect alone.

    The other axis must be running: axis i's drive reaches it through its
    coupling table (which reads axis i's drive), its position and acceleration
    come back through the coupling (the acceleration term is 2.5 x the
    displacement at 650 Hz); with it parked the loop measured 2.4-3.2 x smaller
    at 650-1150 Hz and 43-92 degrees apart, and the learning through it (that
    measurement also a tick off) grew the 650 Hz line from 8.5 to 14.7 nm.
    (Until 2026-11-26: a triangle of axis i's own, 10 % of its stroke, the other
    axis parked; its harmonics fall as 1/k^2, the even ones, which it lacks,
    were interpolated across the 140 Hz mode, and the band stopped at 3 x the
    resonance, below the 620 Hz mode: 9.7 of the 10.3 nm left at 50 Hz lay above it.)"""
    periods = max(2, min(int(round(PROBE_S * f)), ci.rec_frames_capacity(1) // n_ticks - settle))
    c = ilc.probe(n_ticks, f, f_cut, PROBE_RMS_UM)
    ilc.switch_off(ci)
    e0 = _record_periods(ci, n_ticks, periods, settle, preview)
    ilc.upload(ci, c, f)
    e1 = _record_periods(ci, n_ticks, periods, settle, preview)
    ilc.switch_off(ci)
    # the difference of two independent records: E1 - E0 per period pair
    return ilc.loop_from_probe(e1 - e0, c)


_CLEARED_AT_ARM: list = []   # faults found latched when arming during the evaluation (collected per frequency)


def _arm(c, tries: int = 20, wait_s: float = 0.05) -> None:
    """Arm ``c`` after clearing a latched fault (the other axis' parking rings the 140 Hz mode of this one
    through the coupling, and its sensor fault can latch again for a few ms after a clear); each clear is
    recorded in ``_CLEARED_AT_ARM``. A fault that persists stops the arm as before."""
    for _ in range(tries):
        st = c.status()
        if not st["faults"]:
            break
        _CLEARED_AT_ARM.append({"axis": c.identity.axis + 1, "when": "at an arm",
                                "faults": list(st["faults_names"])})
        c.command("clear_faults")
        time.sleep(wait_s)
    c.arm(True)


def _clear_latched(ctls, args, when: str) -> list:
    """Faults latched on any of ``ctls`` (the 140 Hz stage's mode, rung through the coupling or by a learning
    trial, can carry a sensor out of its range): said, recorded and cleared, so the next measurement can arm."""
    out = []
    for c in ctls:
        st = c.status()
        if st["faults"]:
            _log(args, f"axis {c.identity.axis + 1}: faults latched {when}: {', '.join(st['faults_names'])}; cleared")
            c.command("clear_faults")
            out.append({"axis": c.identity.axis + 1, "when": when, "faults": list(st["faults_names"])})
    return out


def evaluate_coupling(ci, cj, comp_i: dict, comp_j: dict, *, trials: int = ILC_TRIALS, args=None) -> dict:
    """Axis i's RMS error [um] holding mid stroke while axis j tracks triangles:
    the coupling table bypassed (uncompensated), applied, and applied with axis
    i's learned feedforward (started in step with axis j's wave)."""
    from .pipeline import _park
    out = {}
    tick = ci.identity.tick_hz
    # the held axis holds a constant: its input shaper has nothing to smooth, and it would keep the learned
    # correction away from the axis' own mode, where the coupling rings it; its preview keeps the lag part
    comp_i = dict(comp_i, shaper_ticks=0, shaper_q15=[32768, 0, 0],
                  preview_ticks=max(0, int(comp_i["preview_ticks"]) - int(comp_i["shaper_ticks"])))

    def at(f):
        _CLEARED_AT_ARM.clear()
        faults = _clear_latched((ci, cj), args, f"before the {f:g} Hz evaluation")
        n = int(round(tick / f))
        periods = max(5, int(round(TRIAL_S * f)))   # a learning trial: the sensor noise averaged down
        # a record starts with the held axis' wave, and its correction with it: the step rings the axis' mode
        # (its shaper is off), 36-45 nm in the first 50 Hz period, halving every 20 ms
        settle = max(settle_periods(f), int(np.ceil(STILL_SETTLE_S * f - 1e-9)))
        p_eval = max(2, min(EVAL_PERIODS, ci.rec_frames_capacity(1) // n - settle))
        f_cut = min(ILC_F_CUT_HZ, 0.4 * ilc.capacity(ci) * f)
        res, per = {}, {}
        for bypass in (1, 0):
            _hold_and_drive(ci, cj, comp_i, comp_j, f, bypass)
            cols = ci.capture(["err"], n * p_eval, trigger="immediate")
            res[bypass] = float(np.sqrt(np.mean(cols["err"] ** 2)))
            per[bypass] = periodic_rms(cols["err"], n)
            _end_other_wave(cj, n)
            for c, comp in ((ci, comp_i), (cj, comp_j)):
                _park(c, c.q15_position(comp["stroke"][0]))
        # a fault while these were measured (the other axis stopped, or this one disarmed) makes them invalid
        table_faults = _clear_latched((ci, cj), args, f"while measuring without and with the coupling table "
                                                      f"at {f:g} Hz")
        # the learned feedforward of the held axis: trials while the other axis keeps running
        _hold_and_drive(ci, cj, comp_i, comp_j, f, 0)
        loop, loop_sigma = _still_loop(ci, n, f, f_cut, settle, comp_i["preview_ticks"])
        rms_all: list = []
        learner = ilc.ILC(n, f, f_cut, alpha=0.5, loop=loop, loop_sigma=loop_sigma, gain_max=ILC_GAIN_MAX)
        ilc.switch_off(ci)

        def trial(c):
            # a refused trial sends the learning back to its best correction, which may be none: then the
            # refused one must stop playing (uploading only nonzero corrections left it on: 4 trials of 50 nm
            # after a 38 nm start, and the learning gave up)
            if np.any(c):
                ilc.upload(ci, c, f)
            else:
                ilc.switch_off(ci)
            return _still_trial(ci, n, periods, settle, comp_i["preview_ticks"], rms_all)

        learned = ilc.learn(trial, learner, trials)
        ilc.upload(ci, learned["best"], f)
        per_learned: list = []
        _still_trial(ci, n, p_eval, settle, comp_i["preview_ticks"], rms_all, per_learned)
        ilc_rms = rms_all[-1]   # the best correction, played in step, measured like the others
        ilc.switch_off(ci)
        # the learning's faults are read before the other axis' wave ends, so that a fault of its end
        # (none expected now it ends at its offset) is not counted as one of the learning
        learn_faults = _clear_latched((ci, cj), args, f"while learning at {f:g} Hz")
        _end_other_wave(cj, n)
        end_faults = _clear_latched((ci, cj), args, f"when the other axis' {f:g} Hz wave ended")
        faults += table_faults + learn_faults + end_faults + _CLEARED_AT_ARM
        _CLEARED_AT_ARM.clear()
        # a fault during the learning makes its figures invalid: the coupling table alone is what holds
        used = "table" if learn_faults else "learned"
        com = res[0] if learn_faults else ilc_rms
        per_com = per[0] if learn_faults else per_learned[0]
        for c, comp in ((ci, comp_i), (cj, comp_j)):
            _park(c, c.q15_position(comp["stroke"][0]))
        ci.configure("xcouple_bypass", 0)
        _log(args, f"axis {ci.identity.axis + 1}, other axis' {f:g} Hz triangle: {res[1] * 1e3:.1f} nm, "
                   f"coupling table {res[0] * 1e3:.1f} nm, + learned {ilc_rms * 1e3:.1f} nm "
                   f"({len(learned['history'])} trials, {learned['refused']} refused)")
        entry = {"rmse_uncompensated_um": res[1], "rmse_compensated_um": com,
                         "rmse_table_only_um": res[0], "compensation_used": used, "faults_cleared": faults,
                         # the figures hold only if neither axis faulted while the table's were measured
                         "valid": not table_faults,
                         "periods": p_eval,
                         # what repeats with the other axis' period (noise-corrected, periodic_rms): the
                         # coupling's error; the rest is the sensor's noise
                         "rmse_periodic_uncompensated_um": per[1][0], "rmse_periodic_table_only_um": per[0][0],
                         "rmse_periodic_um": per_com[0], "noise_rms_um": per[1][1],
                         "reduction_periodic": per[1][0] / per_com[0] if per_com[0] > 0 else float("inf"),
                         "reduction": res[1] / com if com > 0 else float("inf"),
                         "learned": {"trials": len(learned["history"]), "refused": learned["refused"],
                                     "trial_rms_um": rms_all[:-1],
                                     # what repeated in each trial (ilc.periodic_score: the learning's measure)
                                     "trial_periodic_um": [h["score_um"] for h in learned["history"]],
                                     "f_cut_hz": f_cut, "trial_periods": periods}}
        return entry

    for f in EVAL_FREQS:
        # a fault during the evaluation (the other axis stopped, or the learning ran into its sensor's
        # range) makes its figures invalid: measured once more; the second attempt stands, with its faults
        for attempt in (1, 2):
            entry = at(f)
            if not entry["faults_cleared"]:
                break
            _log(args, f"{f:g} Hz: faults during attempt {attempt}: "
                       + ("measured again" if attempt == 1 else "kept, with its faults"))
        entry["attempts"] = attempt
        out[f"{f:g}"] = entry
    return out


def _comp_of(summary: dict, out: pathlib.Path) -> dict:
    """The axis' compensated configuration and the stroke it was calibrated over [um]."""
    from ..io.recording import load_recording
    c = dict(summary["compensation"])
    y = load_recording(out / summary["files"]["data"] / "sweep_0.csv").y
    c["stroke"] = (float(np.min(y)), float(np.max(y)))
    return c


def calibrate_two_axis(c1, port: str, out: pathlib.Path, summary1: dict, *, kinds=("eupi", "kp"),
                       args=None) -> dict:
    """Axis 2's own calibration into ``out/axis2``, then the coupling both ways; returns axis 1's summary with ``coupling``."""
    from .pipeline import calibrate
    from .report import append_coupling_html
    t0 = time.monotonic()
    c2 = connect_axis(port, 2)
    if c2.identity.axis != 1:
        raise CliError(f"{port}: axis 2 answers as axis {c2.identity.axis + 1}")
    _log(args, "axis 2: its own calibration")
    summary2 = calibrate(c2, out / "axis2", kinds=kinds, target=summary1.get("target"), args=args)
    ctls = {1: c1, 2: c2}
    sums = {1: summary1, 2: summary2}
    dirs = {1: out, 2: out / "axis2"}
    for a, c in ctls.items():
        # a fault latched while this axis sat disarmed during the other's calibration
        # (the other's resonance rings it through the coupling): reported, cleared; a
        # persistent one latches again and stops the arm below
        st = c.status()
        if st["faults"]:
            _log(args, f"axis {a}: faults latched while idle: {', '.join(st['faults_names'])}; cleared")
            c.command("clear_faults")
    coupling = {}
    for i, j in ((1, 2), (2, 1)):
        ci, cj = ctls[i], ctls[j]
        data = identify_coupling(ci, cj)
        settings = dict(KERNEL_SETTINGS)
        params = ham.fit_arrays(data["u"], data["x"], data["y"], **settings)
        resid = [float(np.sqrt(np.mean((y - ham.predict(params, u, x)) ** 2)) / np.ptp(y))
                 for u, x, y in zip(data["u"], data["x"], data["y"])]
        line = _line_gain(dirs[i], ci)
        drive_per_um = line / ci.scale.p_half
        tab = coupling_table(params, cj.scale, ci.scale, drive_per_um, x_source=0,
                             table_version=int(time.time()), fit_nrmse=float(np.mean(resid)),
                             build_time=int(time.time()), axis=ci.identity.axis, stage=ci.scale)
        (out / f"coupling_table_axis{i}.bin").write_bytes(tab.image)
        crc = flash_coupling(ci, tab.image)
        ev = evaluate_coupling(ci, cj, _comp_of(sums[i], dirs[i]), _comp_of(sums[j], dirs[j]), args=args)
        head = ev["10"]
        coupling[str(i)] = {"from_axis": j, "rmse_uncompensated_um": head["rmse_uncompensated_um"],
                            "rmse_compensated_um": head["rmse_compensated_um"], "reduction": head["reduction"],
                            "by_frequency": ev, "table_crc_hex": f"{crc:#010x}",
                            "table": f"coupling_table_axis{i}.bin", "fit_nrmse": resid,
                            "drive_per_um": drive_per_um, "line_gain": line}
        _log(args, f"axis {i} from axis {j}: table {crc:#010x}; " + ", ".join(
            f"{k} Hz {v['rmse_uncompensated_um'] * 1e3:.1f} -> {v['rmse_compensated_um'] * 1e3:.1f} nm"
            for k, v in ev.items()))
    summary1 = dict(summary1)
    summary1["coupling"] = coupling
    summary1["axes"] = {"2": {"summary": "axis2/summary.json", "model": summary2["model"],
                              "table_crc_hex": summary2["table_crc_hex"], "tracking": summary2["tracking"]}}
    summary1["coupling_duration_s"] = time.monotonic() - t0
    (out / "summary.json").write_text(json.dumps(summary1, indent=2, sort_keys=True))
    append_coupling_html(out / "report.html", coupling)
    return summary1


def _line_gain(axis_dir: pathlib.Path, ctl) -> float:
    """Axis i's uncompensated straight line [drive FS per position FS]: 1 / its static gain,
    from the model its calibration flashed (what the feedback design uses too)."""
    from ..io.modelfile import load_model
    from ..tables.from_model import compile_model
    return float(compile_model(load_model(axis_dir / "model.json"), ctl.scale).line[0])
