"""Signal processing shared by the models, identification and the diagnosis.

Discrete filters that start at the equilibrium of their first input sample (a
recording starts from rest or from a settled state, never from zero), a
zero-order-hold mode, a slew limiter and the low-passed drive rate. Units:
seconds for ``dt`` and time constants, hertz for frequencies; signals keep the
unit of their input.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

__all__ = ["filt", "lowpass", "lowpass_tau", "mode_filter", "slew_limit", "drive_rate", "RATE_CUTOFF_HZ"]

RATE_CUTOFF_HZ = 50.0


def filt(b, a, x) -> np.ndarray:
    """``lfilter(b, a, x)`` starting at the equilibrium of ``x[0]`` (static gain ``sum b / sum a``)."""
    b = np.asarray(b, float)
    a = np.asarray(a, float)
    x = np.asarray(x, float)
    if b.size == 1 and a.size == 1:
        return x * (b[0] / a[0])
    zi = signal.lfilter_zi(b, a)
    if x.ndim == 1:
        return signal.lfilter(b, a, x, zi=zi * x[0])[0]
    return signal.lfilter(b, a, x, axis=0, zi=zi[:, None] * x[0][None, :])[0]


def lowpass(x, hz: float, dt: float) -> np.ndarray:
    """First-order low-pass (pole ``hz`` [Hz], exact for a held input), from equilibrium."""
    c = 1.0 - np.exp(-2.0 * np.pi * float(hz) * dt)
    return filt([c], [1.0, c - 1.0], x)


def lowpass_tau(x, tau_s: float, dt: float) -> np.ndarray:
    """First-order low-pass with time constant ``tau_s`` [s], from equilibrium."""
    c = 1.0 - np.exp(-dt / float(tau_s))
    return filt([c], [1.0, c - 1.0], x)


def mode_filter(freq_hz: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (zero-order hold) unit-gain mode ``w^2 / (s^2 + 2 z w s + w^2)``: (b, a)."""
    w = 2.0 * np.pi * float(freq_hz)
    bd, ad, _ = signal.cont2discrete(([w * w], [1.0, 2.0 * damping * w, w * w]), dt, method="zoh")
    bd = np.ravel(bd)
    return bd, np.ravel(ad)


def slew_limit(u, max_step: float) -> np.ndarray:
    """Limit the change of ``u`` per sample to ``max_step`` (the amplifier's slew rate times dt).

    Only the stretches where the limit acts are stepped in Python; the rest is copied.
    """
    u = np.asarray(u, dtype=float)
    out = u.copy()
    if u.size < 2 or not np.isfinite(max_step):
        return out
    viol = np.flatnonzero(np.abs(np.diff(u)) > max_step) + 1
    if viol.size == 0:
        return out
    n = u.size
    i = int(viol[0])
    prev = float(out[i - 1])
    while i < n:
        d = u[i] - prev
        if d > max_step:
            prev += max_step
        elif d < -max_step:
            prev -= max_step
        else:
            prev = float(u[i])
            out[i] = prev
            k = int(np.searchsorted(viol, i, side="right"))
            if k >= viol.size:
                break
            i = int(viol[k])
            prev = float(out[i - 1])
            continue
        out[i] = prev
        i += 1
    return out


def drive_rate(v, dt: float, cutoff_hz: float = RATE_CUTOFF_HZ) -> np.ndarray:
    """Magnitude of the drive rate [FS/s], low-passed at ``cutoff_hz`` [Hz]."""
    r = np.abs(np.gradient(np.asarray(v, float), dt)) if len(v) > 1 else np.zeros(len(v))
    return lowpass(r, cutoff_hz, dt)
