"""The chirp in bands for a small recorder (``piezoctl.calibrate.excitation``):
joined, the bands' frequency responses give the delay and the resonance that
the calibration's feedback design reads from them."""

import numpy as np
import scipy.signal as sig

from piezoctl.calibrate.excitation import chirp_frf
from piezoctl.calibrate.feedback import group_delay_ticks, resonance_hz

TICK = 10000
F_RES, ZETA, DELAY = 970.0, 0.012, 2


def _stage(u):
    """Two ticks of delay, then a second-order mode (unit DC gain), at the tick rate."""
    w = 2 * np.pi * F_RES
    b, a = sig.cont2discrete(([w * w], [1, 2 * ZETA * w, w * w]), 1 / TICK, method="zoh")[:2]
    y = sig.lfilter(np.ravel(b), a, u)
    return np.concatenate([np.zeros(DELAY), y[:-DELAY]])


def _band(lo, hi, frames=4096, dec=2, seed=0):
    n = frames * dec
    t = np.arange(n) / TICK
    u = 0.01 * sig.chirp(t, lo / 1.25, t[-1], min(hi * 1.25, TICK / (2.5 * dec)))
    y = _stage(u) + 1e-6 * np.random.default_rng(seed).standard_normal(n)
    return {"t": t[::dec], "u": u[::dec], "y": y[::dec], "f_lo": lo, "f_hi": hi}


def test_banded_chirp_gives_the_delay_and_the_resonance():
    edges = (5.0, 60.0, 400.0, 2000.0)
    bands = [_band(lo, hi, seed=k) for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:]))]
    ch = {"t": None, "u": None, "y": None, "bands": bands}
    frf = chirp_frf(ch, fmin=5.0, fmax=2000.0, coherence_min=0.8)
    assert np.all(np.diff(frf.f_hz) > 0)
    f_res = resonance_hz(frf)
    assert abs(f_res - F_RES) < 0.02 * F_RES
    # expected: the delay, half a tick of the zero-order hold, the mode's 2 zeta / w
    expected = DELAY + 0.5 + 2 * ZETA / (2 * np.pi * F_RES) * TICK
    sel = frf.f_hz < f_res / 3.0
    slope = np.polyfit(frf.f_hz[sel], frf.phase_deg[sel], 1, w=frf.mag[sel])[0]
    assert abs(-slope / 360.0 * TICK - expected) < 0.1
    assert group_delay_ticks(frf, TICK, f_res / 3.0) == round(expected)
    # the joined phase is continuous across the band edges
    assert np.max(np.abs(np.diff(frf.phase_deg[frf.f_hz < 800]))) < 20.0


def test_a_phase_that_is_not_a_line_gives_no_delay():
    # round 18: the 140 Hz two-axis stage's coherent points below 47 Hz (calibration L3, axis 1):
    # the phase scatters by +-45 deg about any line; its slope had been read as 32 ticks of delay
    from piezoctl.ident.tf import FRF
    f = np.array([39.7, 40.9, 42.1, 42.7, 43.3, 43.9, 44.6, 45.2, 45.8])
    ph = np.array([27.3, 42.0, 27.8, -25.9, -5.5, -5.0, 37.6, -40.9, 45.4])
    assert group_delay_ticks(FRF(f, np.ones_like(f), ph, None), TICK, 47.0) == 0
    # the same frequencies on a line of 3 ticks (and an offset): read as 3 ticks
    line = -360.0 * f * 3 / TICK - 5.0
    assert group_delay_ticks(FRF(f, np.ones_like(f), line, None), TICK, 47.0) == 3


def test_the_delay_does_not_depend_on_which_noisy_low_lines_pass():
    """Round 21 (CI's 7.4x at 100 Hz): on the default SIL stage the chirp's lines below f_res / 3
    run from 40 Hz, coherence 0.8, to 323 Hz, 0.997, and the magnitude is largest at the noisy low end.
    Weighted by magnitude, the residual about a 2-tick line crossed the 10 deg rule in some draws of the
    noise and the delay (the preview) came out 0; weighted by the lines' precision it is 2 in every draw.
    The model of the lines matches 18 recorded chirps: magnitude-weighted residual 5.5-12.6 deg there,
    8.4-12.7 deg here."""
    from piezoctl.ident.tf import FRF
    f = np.arange(66, 530) * TICK / 16384.0            # the chirp's Welch lines, 40.3 .. 323 Hz
    coh = 1.0 - 0.2 * (40.0 / f) ** 2
    scatter_deg = 50.0 * np.sqrt((1.0 - coh) / coh)   # H1's phase deviation goes as sqrt((1 - c) / c)
    mag = 0.1 * (1.0 + (40.0 / f) ** 2)
    with_coherence, by_magnitude = [], []
    for seed in range(50):
        ph = -360.0 * f * 2 / TICK - 3.0 + scatter_deg * np.random.default_rng(seed).standard_normal(f.size)
        with_coherence.append(group_delay_ticks(FRF(f, mag, ph, coh), TICK, 323.3))
        by_magnitude.append(group_delay_ticks(FRF(f, mag, ph, None), TICK, 323.3))   # no coherence: the old weights
    assert with_coherence == [2] * 50
    assert by_magnitude.count(0) >= 10     # the draws reproduce the flip the precision weights remove
