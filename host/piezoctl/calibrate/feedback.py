"""Dynamics-derived settings: reference preview and the feedback loop.

- Preview: the group delay of the measured frequency response below a
  tenth of the resonance (transport delay, amplifier, the tick itself), in
  ticks; the controller then feeds the reference that many ticks early.
- Input shaper: a zero-vibration-derivative shaper (taps 1, 2K, K^2 over
  (1 + K)^2 at 0, half and one damped period, K = exp(-zeta pi / sqrt(1 -
  zeta^2))) on the feedforward reference, so the compensated drive does not
  ring the first mode; the preview also covers its delay of half a period.
- Feedback: an integral controller (plus a small proportional part) with
  crossover ``fc`` well below the resonance, and a wide notch at the
  resonance (the magnitude peak of the measured response) so the loop gain
  stays below one there. The integral gain per tick is
  ``Ki = 2 pi fc Ts / G0`` with ``G0`` the static gain in q15 units.
"""

from __future__ import annotations

import numpy as np

# the controller's limits (firmware/control/controller.h PIEZO_CTL_MAX_SHAPER, _PREVIEW; the registers
# shaper_ticks and preview_ticks refuse more): a ZVD spacing of 64 ticks is the half period of a
# 78 Hz mode at 10 kHz, and the preview covers the shaper's delay m plus the stage's lag
MAX_SHAPER_TICKS = 64
MAX_PREVIEW_TICKS = 96

__all__ = ["group_delay_ticks", "phase_weights", "resonance_hz", "damping", "zvd_shaper", "notch", "design_feedback"]


PHASE_RESID_MAX_DEG = 10.0   # a delay's phase is a line: beyond this weighted RMS residual it is not one
COHERENCE_CLIP = 0.99   # a line's precision c / (1 - c) at most 99: beyond, leakage and the hysteresis, not noise


def phase_weights(frf, sel) -> np.ndarray:
    """Weights ``1 / sigma`` of the phases of the lines ``sel`` (``np.polyfit``'s ``w``).

    With a coherence (an H1 estimate): the square root of its precision
    ``c / (1 - c)``, ``c`` clipped at :data:`COHERENCE_CLIP` as in the dynamics
    inverse's design (H1's phase variance goes as ``(1 - c) / c``). Without
    one (a response computed from a model, noise-free): the magnitude.
    """
    coh = getattr(frf, "coherence", None)
    if coh is None:
        return np.asarray(frf.mag, dtype=float)[sel]
    c = np.clip(np.asarray(coh, dtype=float)[sel], 0.0, COHERENCE_CLIP)
    return np.sqrt(c / (1.0 - c))


def group_delay_ticks(frf, tick_hz: float, f_max: float) -> int:
    """Ticks of delay: slope of the unwrapped phase [deg] over 0 < f < f_max [Hz],
    each line weighted by its precision (:func:`phase_weights`); 0 when the line
    leaves more than :data:`PHASE_RESID_MAX_DEG` of weighted RMS residual.

    (Round 18: on the 140 Hz two-axis stage the few coherent points below 47 Hz
    scatter by +-70 deg, 25-45 deg RMS about any line; when 8 or more passed the
    coherence the slope was taken, clipped at 32 ticks, and the preview came out
    68 ticks instead of 36: the 50 Hz triangle with preview and shaper 3.12 um
    instead of 0.85, the learning from it 4.59x.)

    (Round 21: until then the lines were weighted by their magnitude. On the
    default stage the magnitude is largest at the chirp's low end, 40-100 Hz,
    where the coherence is 0.8-0.9 and the phase scatters 11-44 deg RMS about
    the line, so those lines set the residual: 5.5-12.6 deg over 18 SIL
    chirps, which of them the coherence lets in being a draw of the sensor
    noise, i.e. of the tick the chirp's command lands on. Above 10 deg (4 of
    18) the delay was 0, the preview 5 ticks instead of 7, and the 100 Hz
    triangle's learned figure 7.2-7.4x instead of 20x: CI's failure of
    ``test_calibrate_meets_the_tracking_goals``. Weighted by precision the same
    18 give 3.3-5.2 deg and 1.78-2.09 ticks (2 in all), the 140 Hz stage's nine
    points still 32 deg.)"""
    sel = frf.f_hz < f_max
    if np.count_nonzero(sel) < 3:
        return 0
    f, ph, w = frf.f_hz[sel], frf.phase_deg[sel], phase_weights(frf, sel)
    line = np.polyfit(f, ph, 1, w=w)
    if np.sqrt(np.average((ph - np.polyval(line, f)) ** 2, weights=w ** 2)) > PHASE_RESID_MAX_DEG:
        return 0   # the phase there is noise: no preview rather than a wrong one
    slope = line[0]  # deg per Hz
    tau = -slope / 360.0
    return int(np.clip(np.round(tau * tick_hz), 0, 32))


def resonance_hz(frf, f_floor: float = 20.0) -> float:
    """Frequency of the largest magnitude above ``f_floor`` and twice the lowest measured frequency [Hz].

    (Not "10x the lowest": where the coherence drops the chirp's low end, the
    lowest kept frequency can be 40 Hz and the 140 Hz mode of a two-axis stage
    would be missed.)"""
    sel = frf.f_hz > max(f_floor, 2 * frf.f_hz[0])
    i = int(np.argmax(np.where(sel, frf.mag, 0.0)))
    return float(frf.f_hz[i])


def damping(frf, f_res: float, default: float = 0.02) -> float:
    """Damping ratio from the half-power width of the resonance peak (default if unresolved)."""
    i = int(np.argmin(np.abs(frf.f_hz - f_res)))
    half = frf.mag[i] / np.sqrt(2.0)
    lo = i
    while lo > 0 and frf.mag[lo] > half:
        lo -= 1
    hi = i
    while hi < frf.f_hz.size - 1 and frf.mag[hi] > half:
        hi += 1
    if lo == 0 or hi == frf.f_hz.size - 1 or hi - lo < 2:
        return default
    return float(np.clip((frf.f_hz[hi] - frf.f_hz[lo]) / (2.0 * f_res), 0.002, 0.3))


def zvd_shaper(f_res: float, zeta: float, tick_hz: float) -> tuple[int, list[int]]:
    """Tap spacing m [ticks] and q15 taps (summing to 32768) of a ZVD shaper."""
    fd = f_res * np.sqrt(1.0 - zeta * zeta)
    m = int(np.round(tick_hz / (2.0 * fd)))
    if not 1 <= m <= MAX_SHAPER_TICKS:
        return 0, [32768, 0, 0]
    k = np.exp(-zeta * np.pi / np.sqrt(1.0 - zeta * zeta))
    a = np.array([1.0, 2 * k, k * k]) / (1.0 + k) ** 2
    q = [int(np.floor(x * 32768 + 0.5)) for x in a]
    q[1] += 32768 - sum(q)
    return m, q


def notch(f0: float, fs: float, q: float = 0.7) -> tuple[float, float, float, float, float]:
    """Notch biquad (b0, b1, b2, a1, a2), a0 = 1, unity gain at DC."""
    w0 = 2 * np.pi * f0 / fs
    alpha = np.sin(w0) / (2 * q)
    a0 = 1 + alpha
    return (1 / a0, -2 * np.cos(w0) / a0, 1 / a0, -2 * np.cos(w0) / a0, (1 - alpha) / a0)


def design_feedback(frf, line_gain: float, tick_hz: float, *, fc_max: float = 120.0,
                    f_res: float | None = None) -> dict:
    """Preview, PI gains and notch for a stage.

    Parameters
    ----------
    frf : FRF
        Measured drive -> position response (V -> um); only its shape is used.
    line_gain : float
        Drive per position of the uncompensated line [FS/FS]: 1 / static gain.
    tick_hz : float
        Control rate [Hz].
    fc_max : float
        Largest crossover [Hz].
    f_res : float, optional
        The identified resonance [Hz] (default :func:`resonance_hz` of ``frf``): passed by the
        calibration so that the notch, the shaper and the report use one value.
    """
    if f_res is None:
        f_res = resonance_hz(frf)
    zeta = damping(frf, f_res)
    fc = min(fc_max, f_res / 8.0)
    ts = 1.0 / tick_hz
    ki = 2 * np.pi * fc * ts * line_gain
    m, taps = zvd_shaper(f_res, zeta, tick_hz)
    # the delay from the phase below a third of the resonance; with fewer than 8
    # coherent points there (a low mode, e.g. 140 Hz, above a chirp whose low end
    # lost coherence) the slope is noise: no preview rather than a wrong one
    enough = np.count_nonzero(frf.f_hz < f_res / 3.0) >= 8
    delay = group_delay_ticks(frf, tick_hz, f_res / 3.0) if enough else 0
    return {"resonance_hz": f_res, "damping": zeta, "crossover_hz": fc, "kp": 0.2 * line_gain, "ki": ki,
            "notch": notch(f_res, tick_hz), "delay_ticks": delay, "shaper_ticks": m, "shaper_q15": taps,
            "preview_ticks": int(min(MAX_PREVIEW_TICKS, delay + m))}
