"""The dynamics inverse: an FIR on the early reference so that stage times filter is a pure delay.

The firmware's filter (``firmware/core/fir.h``, bit-exact twin
:mod:`piezoctl.golden.fir`) runs on the reference ``preview_ticks`` early,
before the table's hysteresis inverse. This module designs its taps from the
calibration's measured frequency response (the chirp, drive -> position),
normalized by its static gain (the hysteresis inverse takes care of the static
part), so that

    G(f) H(f) ~ exp(-j 2 pi f p / fs)

over the band where the response is measured and invertible. With the
preview set to ``p`` ticks the stage then follows the reference on time, for
any reference: a streamed setpoint or a random scan as well as a periodic wave.

The band: from the lowest coherent line up to ``f_hi``, the first line above
the resonance where ``|G|`` falls below ``1 / max_gain`` (inverting further
would amplify more than ``max_gain``), at most the last coherent line and
0.8 of the filter's own Nyquist frequency (``fs / 2d``). Above it the filter
rolls off: a weighted least-squares term pulls ``H`` towards 0 from ``f_hi`` to
``fs / 2d``, so it never amplifies what was not identified or is only noise;
a small ridge term keeps the taps short; the DC gain is held at 1. If the
designed ``|H|`` anywhere exceeds ``max_gain`` the roll-off weight is
raised until it does not. The delay ``p`` is the stage's lag plus half the
taps' span (:func:`preview_for`), at most the firmware's preview limit.

Taps are spaced ``d`` ticks apart (1..8): 32 taps at d = 1 span 3.2 ms, three
periods of a 970 Hz mode; a 140 Hz mode needs d = 5 (a span of 16 ms and a
band edge below 1 kHz).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..golden import fir as gfir
from .feedback import MAX_PREVIEW_TICKS

__all__ = ["DynInverse", "design_dyninv", "preview_for", "spacing_for", "static_gain"]

MAX_GAIN = 3.0          # |H| bound: no frequency is amplified more (also the band's edge: |G| >= 1 / MAX_GAIN)
ROLLOFF_WEIGHT = 0.3    # least-squares weight of |H| -> 0 above the band, relative to the in-band fit
RIDGE = 1e-4            # Tikhonov weight on the taps (relative to the in-band rows' scale)
LOW_FRACTION = 0.1      # the static gain: from the lines below 3x this fraction of the resonance
N_BELOW = 20            # rows between 0 Hz and the lowest coherent line (the stage there: its lag)


@dataclass
class DynInverse:
    """A designed dynamics inverse.

    Attributes
    ----------
    taps : ndarray
        Float taps, newest sample first (``h_k`` weighs ``r(t - k d)``).
    taps_q13 : list of int
        The same in q13 (8192 = 1), what the controller gets (``dyninv_q13``).
    spacing : int
        Ticks between taps ``d`` (``dyninv_ticks``).
    preview_ticks : int
        The delay ``p`` of the target ``G H = z^-p`` [ticks]: the preview to configure.
    band_hz : tuple of float
        The inverted band (lowest coherent line, ``f_hi``) [Hz].
    static_gain : float
        The measured response's static gain the design normalized by [position / drive unit].
    max_gain : float
        ``max |H|`` over 0..fs/2 of the quantized taps.
    inband_error : float
        RMS of ``|G H - z^-p|`` over the band's lines (the quantized taps), each line weighted by its
        precision ``coherence / (1 - coherence)``: 0 is a perfect inverse.
    shaper_error : float or None
        The same figure for the alternative it replaces (preview and ZVD shaper), when given.
    """

    taps: np.ndarray
    taps_q13: list
    spacing: int
    preview_ticks: int
    band_hz: tuple
    static_gain: float
    max_gain: float
    inband_error: float
    shaper_error: float | None = None
    history: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-friendly summary (``summary.json`` ``compensation.dynamics_inverse``)."""
        return {"taps": len(self.taps_q13), "spacing_ticks": self.spacing, "taps_q13": list(self.taps_q13),
                "preview_ticks": self.preview_ticks, "band_hz": [float(b) for b in self.band_hz],
                "static_gain": self.static_gain, "max_gain": self.max_gain,
                "inband_error": self.inband_error, "shaper_inband_error": self.shaper_error}


def preview_for(n_taps: int, spacing: int, lag: int) -> int:
    """The delay ``p`` of the target ``z^-p`` [ticks]: the stage's lag plus half the taps' span, at most the
    firmware's preview limit.

    The inverse of a mode is non-causal in part (it anticipates), so the least-squares FIR
    approximates it best with its centre of mass mid-span. Choosing ``p`` by the least in-band
    error instead picked 36 or 91 ticks on two chirps of the same 140 Hz stage (nearly equal
    errors, lines below 100 Hz noisy), and the 36-tick filter left 6 deg of phase and 10 % of
    gain at 30 Hz: the random scan's error grew from 135 to 227 nm."""
    return int(min(MAX_PREVIEW_TICKS, lag + ((n_taps - 1) * spacing + 1) // 2))


def spacing_for(f_res: float, tick_hz: float, n_taps: int = gfir.MAX_TAPS) -> int:
    """Tap spacing [ticks] so that the taps span at least two periods of the mode ``f_res`` [Hz]."""
    d = int(np.ceil(2.0 * tick_hz / (n_taps * f_res)))
    return int(np.clip(d, 1, gfir.MAX_SPACING))


def _response(taps, spacing: int, f_hz, tick_hz: float) -> np.ndarray:
    """H(f) of taps spaced ``spacing`` ticks apart."""
    k = np.arange(len(taps)) * spacing
    return np.exp(-2j * np.pi * np.outer(f_hz, k) / tick_hz) @ np.asarray(taps, dtype=float)


def static_gain(frf, f_res: float, tick_hz: float, delay_ticks: int = 0) -> float:
    """The measured response's static gain [its units].

    The magnitude of the complex mean, over the lines below ``LOW_FRACTION`` x 3 of the resonance
    (at least the lowest 8), of ``G`` with the lag ``delay_ticks`` and the mode's own rise
    ``1 / (1 - (f / f_res)^2)`` taken out. Complex averaging: the magnitudes of noisy low lines are
    biased upward (on the SIL chirp at 1 % of the range the lines below 100 Hz read 7 % high), their
    mean is not."""
    f = np.asarray(frf.f_hz, dtype=float)
    g = np.asarray(frf.h, dtype=complex) * np.exp(2j * np.pi * f * delay_ticks / tick_hz) * (1.0 - (f / f_res) ** 2)
    low = f < 3.0 * LOW_FRACTION * f_res
    if np.count_nonzero(low) < 8:
        low = np.arange(f.size) < 8
    return float(np.abs(np.mean(g[low])))


def _band(f, g_n, f_res: float, f_nyq: float, max_gain: float) -> float:
    """Upper edge of the inverted band [Hz] (see the module's docstring)."""
    hi = min(float(f[-1]), 0.8 * f_nyq)
    above = np.nonzero((f > f_res) & (np.abs(g_n) < 1.0 / max_gain))[0]
    if above.size:
        hi = min(hi, float(f[above[0]]))
    return hi


def design_dyninv(frf, tick_hz: float, f_res: float, *, n_taps: int = gfir.MAX_TAPS,
                  spacing: int | None = None, max_gain: float = MAX_GAIN, min_delay: int = 0,
                  damping: float = 0.02, preview: int | None = None, shaper: tuple | None = None) -> DynInverse:
    """Least-squares FIR inverse of the measured dynamics.

    Parameters
    ----------
    frf : piezoctl.ident.frf.FRF
        Measured drive -> position response on its coherent lines (any units: it is normalized
        by its static gain, :func:`static_gain`).
    tick_hz : float
        Control rate [Hz].
    f_res : float
        The identified first resonance [Hz].
    n_taps : int
        Taps, 1..32.
    spacing : int, optional
        Ticks between taps (default :func:`spacing_for`).
    max_gain : float
        Bound on ``|H|`` at every frequency, and the band's edge above the resonance.
    min_delay : int
        Smallest delay ``p`` to try [ticks] (e.g. the stage's identified lag).
    preview : int, optional
        The delay ``p`` [ticks] (default :func:`preview_for`).
    damping : float
        The mode's damping ratio: below the lowest coherent line the stage is taken as its lag and
        the mode's second-order response (the same model :func:`static_gain` takes out).
    shaper : (int, list of int), optional
        Preview and ZVD shaper ``(preview_ticks, shaper_ticks, shaper_q15)`` of the feedback design:
        its in-band error is reported beside the inverse's (``shaper_error``).

    Returns
    -------
    DynInverse
    """
    d = int(spacing if spacing is not None else spacing_for(f_res, tick_hz, n_taps))
    f = np.asarray(frf.f_hz, dtype=float)
    g = np.asarray(frf.h, dtype=complex)
    k0 = static_gain(frf, f_res, tick_hz, min_delay)
    g_n = g / k0
    f_nyq = tick_hz / (2.0 * d)
    f_hi = _band(f, g_n, f_res, f_nyq, max_gain)
    inb = f <= f_hi
    fb, gb = f[inb], g_n[inb]
    # rows: in band G H = z^-p, each line weighted by its precision (the H1 estimate's variance goes as
    # (1 - coherence) / coherence) and a little toward low frequencies, where references carry their
    # power; below the lowest coherent line the stage is its lag and the mode's second-order rise
    # (continuous with the lines, normalized as static_gain does); DC gain 1;
    # H -> 0 above the band up to the filter's Nyquist frequency; a ridge on the taps
    w_in = (fb / fb[0]) ** -0.25
    if frf.coherence is not None:
        c2 = np.clip(np.asarray(frf.coherence, dtype=float)[inb], 0.0, 0.99)
        w_in = w_in * np.sqrt(c2 / (1.0 - c2))
    f_below = np.linspace(0.0, fb[0], N_BELOW, endpoint=False)[1:]
    w_below = np.full(f_below.size, float(np.mean(w_in)))
    fb = np.concatenate([f_below, fb])
    x = f_below / f_res
    gb = np.concatenate([np.exp(-2j * np.pi * f_below * min_delay / tick_hz) / (1.0 - x * x + 2j * damping * x), gb])
    w_in = np.concatenate([w_below, w_in])
    w_in /= np.sqrt(np.sum(w_in ** 2))
    f_out = np.linspace(f_hi * 1.25, f_nyq, 200) if f_hi * 1.25 < f_nyq else np.array([f_nyq])
    e_in = np.exp(-2j * np.pi * np.outer(fb, np.arange(n_taps) * d) / tick_hz)
    e_out = np.exp(-2j * np.pi * np.outer(f_out, np.arange(n_taps) * d) / tick_hz)
    a_in = (w_in[:, None] * gb[:, None]) * e_in
    fine = np.linspace(0.0, f_nyq, 2048)

    def solve(p: int, w_out: float):
        rhs_in = w_in * np.exp(-2j * np.pi * fb * p / tick_hz)
        a = np.vstack([a_in, (w_out / np.sqrt(f_out.size)) * e_out])
        b = np.concatenate([rhs_in, np.zeros(f_out.size)])
        a_r = np.vstack([a.real, a.imag, 10.0 * np.ones((1, n_taps)), np.sqrt(RIDGE) * np.eye(n_taps)])
        b_r = np.concatenate([b.real, b.imag, [10.0], np.zeros(n_taps)])
        h = np.linalg.lstsq(a_r, b_r, rcond=None)[0]
        return h

    p = preview_for(n_taps, d, min_delay) if preview is None else int(preview)
    w_out = ROLLOFF_WEIGHT
    history = []
    for _ in range(12):
        h = solve(p, w_out)
        peak = float(np.max(np.abs(_response(h, d, fine, tick_hz))))
        history.append({"rolloff_weight": w_out, "max_gain": peak})
        if peak <= max_gain and np.all(np.abs(h) < 4.0 - 2.0 ** -13):
            break
        w_out *= 2.0
    q = gfir.quantize_taps(h)
    hq = np.asarray(q, dtype=float) / (1 << gfir.FRAC)
    # the figures below: over the measured lines only, each weighted by its precision (an RMS of
    # plain lines would be the noise of the chirp's low end: 0.56 between 40 and 100 Hz on SIL, 0.01
    # from 200 to 1200 Hz)
    meas = f_below.size
    fb, gb = fb[meas:], gb[meas:]
    prec = np.ones(fb.size)
    if frf.coherence is not None:
        c2 = np.clip(np.asarray(frf.coherence, dtype=float)[inb], 0.0, 0.99)
        prec = c2 / (1.0 - c2)
    prec /= np.sum(prec)
    err = gb * _response(hq, d, fb, tick_hz) - np.exp(-2j * np.pi * fb * p / tick_hz)
    shaper_err = None
    if shaper is not None:
        p_s, m, taps_s = shaper
        s_resp = np.ones_like(fb, dtype=complex) if m == 0 else sum(
            (t / 32768.0) * np.exp(-2j * np.pi * fb * i * m / tick_hz) for i, t in enumerate(taps_s))
        e_s = gb * s_resp - np.exp(-2j * np.pi * fb * p_s / tick_hz)
        shaper_err = float(np.sqrt(np.sum(prec * np.abs(e_s) ** 2)))
    return DynInverse(taps=hq, taps_q13=q, spacing=d, preview_ticks=int(p), band_hz=(float(fb[0]), float(f_hi)),
                      static_gain=k0, max_gain=float(np.max(np.abs(_response(hq, d, fine, tick_hz)))),
                      inband_error=float(np.sqrt(np.sum(prec * np.abs(err) ** 2))), shaper_error=shaper_err,
                      history=history)
