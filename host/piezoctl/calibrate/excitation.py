"""Excitation played by the firmware's wave generator and captured by its
recorder, over the protocol: nothing here reaches into the simulation.

- :func:`forc_sweeps`: quasi-static triangles that all start at the bottom of
  the drive range and reach decreasing tops (first-order reversal curves):
  the major loop and nested minor loops. Each recording starts when the
  reference rises through the bottom after a full period, so the stage's
  memory was wiped at the bottom, as the models' reset state assumes.
- :func:`chirp`: a small-amplitude linear chirp around mid-range for the
  frequency response.
"""

from __future__ import annotations

import time

import numpy as np

from .. import interface

__all__ = ["forc_sweeps", "chirp", "chirp_frf", "triangle_run", "multitone_run", "wait_wave_end"]


def forc_sweeps(ctl, tops=(1.0, 0.8, 0.6, 0.4), *, f_hz: float = 1.0, periods: int = 2,
                decimation: int = 4, say=None) -> list[dict]:
    """Triangles from the drive's bottom to ``tops`` (fractions of the range), in DIRECT mode.

    Returns one dict per top with ``t`` [s], ``u`` [V], ``y`` [um]. ``say``, if given, is called
    with a line of progress before each sweep (each takes ``periods / f_hz`` plus the trigger's wait).
    """
    out = []
    tick = ctl.identity.tick_hz
    # a board's recorder is smaller than the SIL's (8192 samples on the
    # STM32F405): decimate more rather than record less
    cap = ctl.identity.rec_capacity // 2
    decimation = max(decimation, int(np.ceil(periods / f_hz * tick / cap)))
    frames = int(round(periods / f_hz * tick / decimation))
    for k, top in enumerate(tops):
        if say is not None:
            say(f"sweep {k + 1} of {len(tops)}: up to {top:.0%} of the drive range ...")
        amp = int(np.floor(top * 32767.0))
        offset = -32768 + amp
        level = -32768 + int(0.02 * 2 * amp)
        ctl.configure_wave("triangle", offset_q15=offset, amplitude_q15=amp, f_hz=f_hz)
        cols = ctl.capture(["u", "y"], frames, decimation=decimation, trigger="rising",
                           trigger_signal="ref", level_q15=level, start_wave=True,
                           timeout_s=(periods + 2) / f_hz * 3 + 5)
        ctl.command("stop_wave")
        out.append({"t": cols["t"], "u": cols["u"], "y": cols["y"], "top": top})
    return out


def chirp(ctl, *, f0: float = 5.0, f1: float = 2000.0, duration_s: float = 3.0, amp_frac: float = 0.01,
          centre_frac: float = 0.5, bands=(5.0, 60.0, 400.0, 2000.0)) -> dict:
    """A linear chirp in DIRECT mode; ``t`` [s], ``u`` [V], ``y`` [um].

    At the full tick rate when the recorder holds ``duration_s`` of two
    signals (the SIL's). A board's recorder (8192 samples on the STM32F405)
    holds 0.4 s: a 5 Hz - 2 kHz chirp that short leaves its low end to a few
    cycles at the edge of the analysis window, and the group delay read from
    it (the preview) came out between 1 and 32 ticks from run to run. Then the
    chirp is played in ``bands`` (edges [Hz]), each swept a quarter beyond its
    edges and recorded whole, every second tick (2.5 samples per period at
    2 kHz); ``bands`` in the result lists each recording with the range it
    measures, and ``t``, ``u``, ``y`` are the recordings one after the other.
    :func:`chirp_frf` estimates the frequency response either way.
    """
    amp = int(amp_frac * 32767)
    offset = int((2 * centre_frac - 1) * 32767)
    tick = ctl.identity.tick_hz
    cap = ctl.identity.rec_capacity // 2
    if duration_s * tick <= cap:
        frames = int(duration_s * tick)
        ctl.configure_wave("chirp", offset_q15=offset, amplitude_q15=amp, f_hz=f0, f_end_hz=f1,
                           duration_s=duration_s)
        cols = ctl.capture(["u", "y"], frames, trigger="software", start_wave=True)
        ctl.command("stop_wave")
        return {"t": cols["t"], "u": cols["u"], "y": cols["y"], "bands": None}
    dec = max(1, min(2, int(tick // (2.5 * f1))))
    frames = cap
    dur = frames * dec / tick
    recs = []
    for lo, hi in zip(bands[:-1], bands[1:]):
        ctl.configure_wave("chirp", offset_q15=offset, amplitude_q15=amp, f_hz=lo / 1.25,
                           f_end_hz=min(hi * 1.25, tick / (2.5 * dec)), duration_s=dur)
        cols = ctl.capture(["u", "y"], frames, decimation=dec, trigger="software", start_wave=True)
        ctl.command("stop_wave")
        recs.append({"t": cols["t"], "u": cols["u"], "y": cols["y"], "f_lo": lo, "f_hi": hi})
    t = np.concatenate([r["t"] + k * dur for k, r in enumerate(recs)])
    return {"t": t, "u": np.concatenate([r["u"] for r in recs]), "y": np.concatenate([r["y"] for r in recs]),
            "bands": recs}


def chirp_frf(ch: dict, *, fmin: float = 5.0, fmax: float = 2000.0, coherence_min: float = 0.8):
    """The frequency response of a :func:`chirp` (Welch H1, ``piezoctl.ident.tf``);
    played in bands, each band's estimate over its own range, joined."""
    from ..ident import tf as tfid
    if not ch.get("bands"):
        return tfid.frf_from_time(ch["t"], ch["u"], ch["y"], fmin=fmin, fmax=fmax, coherence_min=coherence_min)
    parts = []
    for b in ch["bands"]:
        lo, hi = max(fmin, b["f_lo"]), min(fmax, b["f_hi"])
        # three half-overlapping segments: a coherence that means something
        f = tfid.frf_from_time(b["t"], b["u"], b["y"], nperseg=len(b["t"]) // 2, fmin=lo, fmax=hi,
                               coherence_min=coherence_min)
        keep = f.f_hz < hi if b is not ch["bands"][-1] else f.f_hz <= hi
        parts.append(tfid.FRF(f.f_hz[keep], f.mag[keep], f.phase_deg[keep],
                              None if f.coherence is None else f.coherence[keep]))
    f_hz = np.concatenate([p.f_hz for p in parts])
    mag = np.concatenate([p.mag for p in parts])
    # each band's phase is unwrapped on its own; join them continuously
    ph = [parts[0].phase_deg]
    for p in parts[1:]:
        if p.phase_deg.size and ph[-1].size:
            p_shift = 360.0 * np.round((ph[-1][-1] - p.phase_deg[0]) / 360.0)
            ph.append(p.phase_deg + p_shift)
        else:
            ph.append(p.phase_deg)
    coh = None if any(p.coherence is None for p in parts) else np.concatenate([p.coherence for p in parts])
    return tfid.FRF(f_hz, mag, np.concatenate(ph), coh)


MULTITONE_HZ = (1.0, 7.0, 23.0)   # the acceptance's multitone [Hz]
SETTLE_S = 0.05   # at least this long before a periodic run is measured [s]


def settle_periods(f_hz: float) -> int:
    """Whole periods of ``f_hz`` [Hz] that last at least :data:`SETTLE_S` (at least one).

    A wave starts wherever the last one was stopped: the reference steps to
    its start, the hysteresis and the loop's integrator start from that state,
    and on the SIL stage the error takes 30-50 ms to become periodic (a 100 Hz
    triangle with its learned feedforward: 836, 339, 164, 115, 100, 96, 96 nm
    RMS in its first seven periods).
    """
    return max(1, int(np.ceil(SETTLE_S * f_hz - 1e-9)))


def _ticks(ctl) -> int:
    """The controller's tick counter (input ``tick_count``, wraps at 2^32)."""
    return ctl.client.read_input_u32(interface.INPUT_REGISTERS["tick_count"][0])


def wait_wave_end(ctl, max_ticks: int, *, poll_s: float = 0.01) -> bool:
    """Wait until a wave that ends by itself (``wave_cycles``) has ended.

    The limit is counted in the controller's ticks, not in the host's time:
    a host that is slow to ask (a loaded PC) never stops the wave early, and
    a controller that stalls is waited for. True if the wave ended by itself
    within ``max_ticks`` ticks of the call; False if it still ran then (the
    caller stops it and says so).
    """
    t0 = _ticks(ctl)
    while ctl.status()["wave_running"]:
        if (_ticks(ctl) - t0) & 0xFFFFFFFF > max_ticks:
            return False
        time.sleep(poll_s)
    return True


def _settled_capture(ctl, period_s: float, periods: int, settle_periods: int, *, ends_itself: bool = False) -> dict:
    """Start the loaded wave, record ``ref`` and ``y`` over ``periods`` after ``settle_periods``.

    ``ends_itself`` (a triangle or a sine): the wave is told to end by itself one
    period after the record (``wave_cycles``), back at its offset, on a tick the
    firmware counts; nothing the host does (or how late) changes the run. Until
    2026-11-26 the host stopped every run with ``stop_wave`` once it had read the
    record: at a phase set by the host's speed, a step of up to the amplitude that
    can ring the stage's mode past the sensor's range (``sensor_implausible``)
    after a valid record, and the configuration was then reported as faulted
    (docs/calibrate.md, "Host timing"). A multisine has no cycles: the host still
    stops it, and ``faults_in_record`` (the faults read before that stop) tells
    a fault of the run from one the stop latched.

    Returns ``t`` [s], ``ref``, ``y`` [um], ``faults_in_record`` (int, the fault
    bits before the host touched the wave) and ``stopped_by_host`` (bool).
    """
    tick = ctl.identity.tick_hz
    total_s = period_s * (periods + settle_periods)
    cap = ctl.identity.rec_capacity // 2
    dec = max(1, int(np.ceil(total_s * tick / cap)))
    frames = int(round(total_s * tick / dec))
    if ends_itself:
        ctl.write("wave_cycles", periods + settle_periods + 1)
    cols = ctl.capture(["ref", "y"], frames, decimation=dec, trigger="software", start_wave=True)
    period_ticks = int(round(period_s * tick))
    stopped_by_host = not (ends_itself and wait_wave_end(ctl, 2 * period_ticks + frames * dec))
    faults = int(ctl.status()["faults"])
    if stopped_by_host:
        ctl.command("stop_wave")
    keep = cols["t"] >= settle_periods * period_s - 1e-12
    return {"t": cols["t"][keep] - cols["t"][keep][0], "ref": cols["ref"][keep], "y": cols["y"][keep],
            "faults_in_record": faults, "stopped_by_host": stopped_by_host}


def triangle_run(ctl, f_hz: float, centre_um: float, amp_um: float, *, periods: int = 2,
                 settle: int | None = None) -> dict:
    """Play a position triangle in the current mode; ``ref`` and ``y`` [um] over whole periods after settling."""
    load_triangle(ctl, f_hz, centre_um, amp_um)
    return _settled_capture(ctl, 1.0 / f_hz, periods, settle_periods(f_hz) if settle is None else settle,
                            ends_itself=True)


def load_triangle(ctl, f_hz: float, centre_um: float, amp_um: float) -> None:
    """Load (not start) the position triangle of :func:`triangle_run`."""
    ctl.configure_wave("triangle", offset_q15=ctl.q15_position(centre_um),
                       amplitude_q15=int(round(amp_um / ctl.scale.p_half * 32768)), f_hz=f_hz)


def load_multitone(ctl, freqs=MULTITONE_HZ, centre_um: float = 0.0, amp_um: float = 1.0) -> None:
    """Load (not start) the multitone of :func:`multitone_run`."""
    each = int(round(amp_um / len(freqs) / ctl.scale.p_half * 32768))
    ctl.configure_wave("multisine", offset_q15=ctl.q15_position(centre_um),
                       tones=[(each, f, 0.0) for f in freqs])


def multitone_run(ctl, freqs=MULTITONE_HZ, centre_um: float = 0.0, amp_um: float = 1.0,
                  *, periods: int = 1, settle_periods: int = 1) -> dict:
    """A multitone (equal amplitudes summing to ``amp_um``) over whole periods of the lowest tone."""
    load_multitone(ctl, freqs, centre_um, amp_um)
    return _settled_capture(ctl, 1.0 / min(freqs), periods, settle_periods)


RANDOM_SCAN_TONES = 8     # the wave generator's multisine holds 8 tones
RANDOM_SCAN_SEED = 15
RANDOM_SCAN_F_LO = 3.0    # the random scan's band starts here [Hz]
RANDOM_SCAN_WINDOW_S = 0.2   # measured over this long after SETTLE_S [s]


def random_scan_tones(f_hi: float, *, f_lo: float = RANDOM_SCAN_F_LO, seed: int = RANDOM_SCAN_SEED,
                      n: int = RANDOM_SCAN_TONES) -> list[tuple[float, float]]:
    """A band-limited random scan: ``n`` tones at random frequencies, uniform over
    [``f_lo``, ``f_hi``] [Hz] (a flat spectrum, as band-limited noise has), random phases [rad];
    (frequency, phase) each. Not periodic within any run (the frequencies are not harmonics of
    one another): no learning has seen it."""
    rng = np.random.default_rng(seed)
    f = np.sort(rng.uniform(f_lo, max(f_hi, 2 * f_lo), n))
    return [(float(x), float(p)) for x, p in zip(f, rng.uniform(0.0, 2 * np.pi, n))]


def random_scan_run(ctl, centre_um: float, amp_um: float, f_hi: float, *,
                    seed: int = RANDOM_SCAN_SEED) -> dict:
    """Play :func:`random_scan_tones` (equal amplitudes summing to ``amp_um``) in the current mode;
    ``ref`` and ``y`` [um] over :data:`RANDOM_SCAN_WINDOW_S` after :data:`SETTLE_S`."""
    tones = random_scan_tones(f_hi, seed=seed)
    each = int(round(amp_um / len(tones) / ctl.scale.p_half * 32768))
    ctl.configure_wave("multisine", offset_q15=ctl.q15_position(centre_um),
                       tones=[(each, f, ph) for f, ph in tones])
    return _settled_capture(ctl, SETTLE_S, int(round(RANDOM_SCAN_WINDOW_S / SETTLE_S)), 1)
