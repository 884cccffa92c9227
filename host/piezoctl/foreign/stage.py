"""The foreign stage: amplifier, hysteresis law, creep, modes, drift, coupling, sensor.

Signal chain of :meth:`Stage.run` (every block independent of the project's own stage
model; ranges in docs/foreign-stage.md)::

    u [V] -> amplifier: gain, offset, slew limit, first-order bandwidth, rails, delay
          -> normalized drive v = (u_a - 75 V) / 75 V
          -> hysteresis law H (optionally rate-dependent: width x (1 + k rho / (1 + rho)))
          -> asymmetric extra beyond a knee on one side of the range   [um from here on]
          -> creep: band-limited log law, step response g log10((1 + t/t0) / (1 + t/t1))
          -> mechanical modes: sum of 1..3 second-order modes, DC gain 1
          -> + cross-axis coupling c * x2, x2 = other axis (its own mode) driven by u2
          -> + thermal drift d(session time), independent of the drive
          -> sensor: gain, nonlinearity and offset (per session), noise, quantization

Each effect is a field; ``None`` (or 0) switches it off.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.signal import cont2discrete, fftconvolve, lfilter, lfilter_zi

from .hysteresis import Law, monotone_runs

__all__ = ["FS_HZ", "U_MID_V", "U_HALF_V", "Mode", "Creep", "Drift", "Coupling", "RateDependence",
           "Asymmetry", "Sensor", "Stage", "mode_filter", "play"]

FS_HZ = 10_000.0        # sample rate [Hz]
U_MID_V = 75.0          # drive mapped to v = 0 [V]
U_HALF_V = 75.0         # drive span mapped to v = +-1 [V]


@dataclasses.dataclass
class Mode:
    """A second-order mode: frequency ``f_hz`` [Hz], damping ratio ``zeta`` [-] and
    residue ``r`` [-] (share of the static gain; the residues of a stage sum to 1)."""

    f_hz: float
    zeta: float
    r: float


def mode_filter(f_hz: float, zeta: float, fs: float = FS_HZ):
    """Discrete (ZOH) coefficients (b, a) of w^2 / (s^2 + 2 zeta w s + w^2), DC gain 1."""
    w = 2 * math.pi * f_hz
    b, a, _ = cont2discrete(([w * w], [1.0, 2 * zeta * w, w * w]), 1 / fs, method="zoh")
    return np.ravel(b), np.ravel(a)


def _filt(b, a, x):
    return lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])[0]


def play(x: np.ndarray, r: float, start: float | None = None) -> np.ndarray:
    """Play (backlash) operator of half-width r [unit of x], starting at ``start``
    (default ``x[0]``)."""
    out = np.empty(x.size)
    p = x[0] if start is None else start
    p = min(max(p, x[0] - r), x[0] + r)
    out[0] = p
    for s, e, d in monotone_runs(x):
        seg = x[s + 1:e + 1]
        if d > 0:
            q = np.maximum(p, np.maximum.accumulate(seg - r))
        else:
            q = np.minimum(p, np.minimum.accumulate(seg + r))
        out[s + 1:e + 1] = q
        if q.size:
            p = q[-1]
    return out


@dataclasses.dataclass
class Creep:
    """Band-limited logarithmic creep: the response to a unit step of the rate-independent
    displacement is ``1 + g log10((1 + t/t0_s) / (1 + t/t1_s))`` (g per decade [-],
    t0_s < t1_s [s]); it saturates after t1_s at ``1 + g log10(t1_s / t0_s)``."""

    g: float
    t0_s: float
    t1_s: float

    def kernel(self, t: np.ndarray) -> np.ndarray:
        """Step response minus 1 at times t [s] (dimensionless)."""
        return self.g * np.log10((1 + t / self.t0_s) / (1 + t / self.t1_s))


@dataclasses.dataclass
class Drift:
    """Thermal drift [um] on the session clock ts [s], independent of the drive: a
    first-order warm-up of amplitude ``a_um`` that starts at ``t_on_s`` with time constant
    ``tau_s``, plus slow sines (amplitudes ``b_um``, periods ``p_s``, phases ``ph``)."""

    a_um: float
    t_on_s: float
    tau_s: float
    b_um: tuple = ()
    p_s: tuple = ()
    ph: tuple = ()

    def __call__(self, ts: np.ndarray) -> np.ndarray:
        x = np.clip(ts - self.t_on_s, 0, None)
        d = self.a_um * (1 - np.exp(-x / self.tau_s))
        for b, p, ph in zip(self.b_um, self.p_s, self.ph):
            d = d + b * (np.sin(2 * np.pi * x / p + ph) - np.sin(ph)) * (ts > self.t_on_s)
        return d


@dataclasses.dataclass
class Coupling:
    """Cross-axis coupling: the other axis moves ``x2 = k2_um_per_v * M(u2)`` through its
    own mode M (``f2_hz``, ``zeta2``); the measured axis gets ``c * x2`` [-]."""

    c: float
    k2_um_per_v: float
    f2_hz: float
    zeta2: float


@dataclasses.dataclass
class RateDependence:
    """Loop widening with rate: the law's width is multiplied by ``1 + k rho / (1 + rho)``,
    rho = |du_a/dt| low-passed (``tau_s`` [s]) over ``rate_ref_v_per_s`` [V/s]."""

    k: float
    rate_ref_v_per_s: float
    tau_s: float = 0.005


@dataclasses.dataclass
class Asymmetry:
    """Asymmetric hysteresis beyond ``knee_v`` [V] on one side of the drive range (``side``
    +1: above the knee, -1: below it): an extra displacement
    ``side * a_um * (relu(side * (play_r(u_a) - knee)) / 30 V)^p``, a softening with its own
    backlash of half-width ``r_v`` [V]; zero on the other side of the knee."""

    a_um: float
    p: float
    r_v: float
    knee_v: float = 0.0
    side: int = -1


@dataclasses.dataclass
class Sensor:
    """Displacement sensor: reading ``gain x + nl + offset + noise``, quantized.

    ``nl_by_session`` [-] maps a session to the nonlinearity size as a fraction of the
    half stroke (capacitive-gap law ``lam q^2 / (1 - lam q)`` normalized to 1 at its
    largest on q in [-1, 1], q = position about mid-stroke), ``offset_by_session`` [um]
    maps a session to the offset; sessions not listed use session 0's value."""

    gain: float
    noise_um: float
    lsb_um: float
    offset_by_session: dict
    nl_by_session: dict
    lam: float = 0.2

    def read(self, x, session, half_stroke_um, mid_um, rng):
        """Measured displacement [um] for true displacement x [um]."""
        off = self.offset_by_session.get(session, self.offset_by_session.get(0, 0.0))
        eps = self.nl_by_session.get(session, self.nl_by_session.get(0, 0.0))
        y = self.gain * x + off
        if eps:
            q = (x - mid_um) / half_stroke_um
            qq = np.linspace(-1, 1, 201)
            norm = np.max(np.abs(self.lam * qq ** 2 / (1 - self.lam * qq)))
            y = y + eps * half_stroke_um * (self.lam * q ** 2 / (1 - self.lam * np.clip(q, -2, 2))) / norm
        y = y + self.noise_um * rng.standard_normal(x.size)
        return np.round(y / self.lsb_um) * self.lsb_um


@dataclasses.dataclass
class Stage:
    """One foreign stage (one measured axis, optionally a second axis that couples in).

    Attributes
    ----------
    law : Law
        Rate-independent hysteresis (normalized).
    stroke_um : float
        Displacement span of the major loop over 0..150 V [um].
    amp_gain, amp_offset_v : float
        Amplifier gain error [-] and offset [V].
    rails_v : (float, float)
        Amplifier output limits [V].
    slew_v_per_s : float or None
        Amplifier slew limit [V/s].
    amp_fc_hz : float or None
        Amplifier first-order bandwidth [Hz].
    delay_samples : int
        Latency [samples at 10 kHz], at least 1.
    modes : list of Mode
        Mechanical modes (residues sum to 1).
    creep, drift, coupling, rate, asym : effect or None
    sensor : Sensor
    """

    law: Law
    stroke_um: float
    amp_gain: float
    amp_offset_v: float
    rails_v: tuple
    modes: list
    sensor: Sensor
    delay_samples: int = 1
    slew_v_per_s: float | None = None
    amp_fc_hz: float | None = None
    creep: Creep | None = None
    drift: Drift | None = None
    coupling: Coupling | None = None
    rate: RateDependence | None = None
    asym: Asymmetry | None = None
    fs: float = FS_HZ

    def amplifier(self, u: np.ndarray) -> np.ndarray:
        """Amplifier output [V] for drive command u [V]."""
        ua = self.amp_gain * np.asarray(u, dtype=float) + self.amp_offset_v
        if self.slew_v_per_s:
            step = self.slew_v_per_s / self.fs
            out = np.empty(ua.size)
            x = float(ua[0])
            vals = ua.tolist()
            for i, target in enumerate(vals):      # scalar loop: ~0.3 s per 1e6 samples
                dx = target - x
                x = x + (step if dx > step else -step if dx < -step else dx)
                out[i] = x
            ua = out
        if self.amp_fc_hz:
            p = math.exp(-2 * math.pi * self.amp_fc_hz / self.fs)
            ua = _filt([1 - p], [1, -p], ua)
        ua = np.clip(ua, *self.rails_v)
        d = int(self.delay_samples)
        if d > 0:
            ua = np.concatenate((np.full(d, ua[0]), ua[:-d]))
        return ua

    def displacement(self, u, u2=None, t_session=0.0, pre_s=30.0) -> np.ndarray:
        """True displacement [um] (before the sensor).

        Parameters
        ----------
        u : ndarray, shape (T,)
            Drive command [V].
        u2 : ndarray, shape (T,), optional
            Drive of the other axis [V].
        t_session : float
            Session time of the first sample [s] (drift clock).
        pre_s : float
            The drive sat at u[0] for this long [s] before the recording (creep history).
        """
        u = np.asarray(u, dtype=float)
        ua = self.amplifier(u)
        v = (ua - U_MID_V) / U_HALF_V
        width = None
        if self.rate is not None and self.law.rate_capable:
            rate = np.abs(np.gradient(ua)) * self.fs
            p = math.exp(-1 / (self.rate.tau_s * self.fs))
            rho = _filt([1 - p], [1, -p], rate) / self.rate.rate_ref_v_per_s
            width = 1 + self.rate.k * rho / (1 + rho)
        x = 0.5 * self.stroke_um * (self.law(v, width) + 1)
        if self.asym is not None:
            a = self.asym
            pv = play(ua, a.r_v)
            x = x + a.side * a.a_um * (np.clip(a.side * (pv - a.knee_v), 0, None) / 30.0) ** a.p
        if self.creep is not None:
            t = np.arange(x.size) / self.fs
            k = self.creep.kernel(t)
            dx = np.diff(x, prepend=x[0])
            x = x + fftconvolve(dx, k)[:x.size] + x[0] * self.creep.kernel(t + pre_s)
        y = np.zeros_like(x)
        for m in self.modes:
            b, a = mode_filter(m.f_hz, m.zeta, self.fs)
            y += m.r * _filt(b, a, x)
        if self.coupling is not None and u2 is not None:
            c = self.coupling
            b, a = mode_filter(c.f2_hz, c.zeta2, self.fs)
            x2 = c.k2_um_per_v * _filt(b, a, np.asarray(u2, dtype=float))
            y += c.c * x2
        if self.drift is not None:
            y += self.drift(t_session + np.arange(y.size) / self.fs)
        return y

    def run(self, u, u2=None, t_session=0.0, session=0, pre_s=30.0, rng=None) -> np.ndarray:
        """Measured displacement [um]: :meth:`displacement` through the sensor.

        ``session`` selects the sensor's offset and nonlinearity; ``rng`` draws the noise
        (default: a fixed seed)."""
        rng = np.random.default_rng(0) if rng is None else rng
        x = self.displacement(u, u2, t_session, pre_s)
        return self.sensor.read(x, session, 0.5 * self.stroke_um, 0.5 * self.stroke_um, rng)
