"""Drive signals users record (all in V, sampled at 10 kHz): decaying sines, FORC sweeps,
random walks, triangles, chirps, sines, steps with dwell."""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

from .stage import FS_HZ

__all__ = ["decaying_sine", "forc", "random_walk", "triangle", "chirp", "sines", "steps", "hold",
           "smooth"]


def _t(dur_s: float) -> np.ndarray:
    return np.arange(int(round(dur_s * FS_HZ))) / FS_HZ


def smooth(u: np.ndarray, fc_hz: float) -> np.ndarray:
    """Zero-phase 4th-order low-pass of a designed drive at fc_hz [Hz] (rounds corners)."""
    if fc_hz >= 0.45 * FS_HZ:
        return u
    sos = butter(2, fc_hz, fs=FS_HZ, output="sos")
    pad = np.concatenate((np.full(2000, u[0]), u, np.full(2000, u[-1])))
    return sosfiltfilt(sos, pad)[2000:-2000]


def decaying_sine(dur_s, f_hz, lo_v, hi_v, tau_s):
    """Sine about the middle of [lo_v, hi_v] [V], amplitude decaying from full with tau_s [s]."""
    t = _t(dur_s)
    c, a = (lo_v + hi_v) / 2, (hi_v - lo_v) / 2
    return c + a * np.exp(-t / tau_s) * np.sin(2 * np.pi * f_hz * t)


def _piecewise(points, rate_v_per_s):
    """Straight lines through the points [V] at a constant rate [V/s]."""
    out = [np.array([points[0]], dtype=float)]
    for a, b in zip(points[:-1], points[1:]):
        n = max(int(round(abs(b - a) / rate_v_per_s * FS_HZ)), 1)
        out.append(a + (b - a) * np.arange(1, n + 1) / n)
    return np.concatenate(out)


def forc(lo_v, hi_v, n_rev, rate_v_per_s, start_v=None):
    """First-order reversal curves: up to hi_v, then for each reversal point (from near hi_v
    down to lo_v) down to it and back up to hi_v; starts and ends at ``start_v``."""
    start_v = (lo_v + hi_v) / 2 if start_v is None else start_v
    pts = [start_v, hi_v]
    for b in np.linspace(hi_v - (hi_v - lo_v) / n_rev, lo_v, n_rev):
        pts += [b, hi_v]
    pts.append(start_v)
    return _piecewise(pts, rate_v_per_s)


def random_walk(dur_s, lo_v, hi_v, fc_hz, rng):
    """Band-limited random drive (white noise low-passed at fc_hz [Hz], zero phase) spread over
    [lo_v, hi_v] [V]; starts in the middle."""
    n = int(round(dur_s * FS_HZ))
    w = smooth(rng.standard_normal(n), fc_hz)
    w = w - w[0]
    w = w / max(np.max(np.abs(w)), 1e-12)
    return (lo_v + hi_v) / 2 + (hi_v - lo_v) / 2 * w


def triangle(dur_s, f_hz, lo_v, hi_v):
    """Triangle between lo_v and hi_v [V] at f_hz [Hz], starting in the middle going up."""
    t = _t(dur_s)
    ph = (f_hz * t + 0.25) % 1.0
    tri = np.where(ph < 0.5, 4 * ph - 1, 3 - 4 * ph)
    return (lo_v + hi_v) / 2 + (hi_v - lo_v) / 2 * tri


def chirp(dur_s, f0_hz, f1_hz, amp_v, center_v):
    """Logarithmic chirp from f0_hz to f1_hz [Hz], amplitude amp_v [V] about center_v [V], with
    0.2 s raised-cosine tapers."""
    t = _t(dur_s)
    k = np.log(f1_hz / f0_hz) / dur_s
    ph = 2 * np.pi * f0_hz * (np.exp(k * t) - 1) / k
    env = np.ones_like(t)
    m = min(int(0.2 * FS_HZ), t.size // 4)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(m) / m)
    env[:m], env[-m:] = ramp, ramp[::-1]
    return center_v + amp_v * env * np.sin(ph)


def sines(freqs_hz, amp_v, center_v, each_s):
    """Consecutive sines (a whole number of periods each, at least ``each_s`` [s])."""
    out = []
    for f in freqs_hz:
        n = int(np.ceil(each_s * f)) / f
        t = _t(n)
        out.append(center_v + amp_v * np.sin(2 * np.pi * f * t))
    return np.concatenate(out)


def steps(levels_v, dwell_s, ramp_s=0.0):
    """Steps to each level [V], each held dwell_s [s]; edges ramped over ramp_s [s] (0: a
    one-sample jump)."""
    out = [np.full(int(round(dwell_s * FS_HZ)), levels_v[0], dtype=float)]
    for a, b in zip(levels_v[:-1], levels_v[1:]):
        nr = int(round(ramp_s * FS_HZ))
        if nr > 0:
            out.append(a + (b - a) * np.arange(1, nr + 1) / nr)
        out.append(np.full(int(round(dwell_s * FS_HZ)), b, dtype=float))
    return np.concatenate(out)


def hold(dur_s, level_v):
    """Constant drive [V]."""
    return np.full(int(round(dur_s * FS_HZ)), float(level_v))
