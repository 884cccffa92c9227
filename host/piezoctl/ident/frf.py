"""Frequency responses from time-domain records: the H1 estimate, its gaps and its coherence.

The estimate (:func:`estimate`) is Welch's H1,

.. math::

    H_1(f) = \\frac{P_{uy}(f)}{P_{uu}(f)}, \\qquad
    \\gamma^2(f) = \\frac{|P_{uy}(f)|^2}{P_{uu}(f)\\,P_{yy}(f)},

with Hann-windowed segments of ``nperseg`` samples overlapping by half
(``scipy.signal.welch``/``csd``, each segment's mean removed). Every Welch line
in the band is kept in the :class:`FRFEstimate` with the reason it is used or
not: a line is **used** when the input has power there (at least
``power_min`` of the in-band maximum) and its coherence is at least
``coherence_min``.

What the estimate cannot tell (``docs/dynamics.md``, "Gaps and coherence"):

- **Gaps.** A run of at least :data:`GAP_MIN_LINES` unused lines between two
  used ones is a band without data: a transfer function fitted to the used
  lines is free to put a resonance there. :func:`find_gaps` finds them from the
  used lines and the line spacing (``resolution_hz``), so it works on an FRF
  file as well as on an estimate.
- **Coherence.** Below :data:`LOW_COHERENCE` the output is not explained by a
  linear response to the input (noise, nonlinearity, leakage at a sharp
  resonance); the magnitude there is biased low.
- :func:`check_resonances` flags each lightly damped pole pair of a fitted
  model whose natural frequency lies outside the used band, inside a gap, or
  where the coherence is low.

Also here: :func:`sample_rate`, the rule for the time column (one rule for the
FRF estimate and for ``piezoctl simulate --stage``), and :class:`FRF`, a
frequency response on its used lines (what ``fit-tf`` fits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "FRF",
    "FRFEstimate",
    "Gap",
    "estimate",
    "frf_from_time",
    "find_gaps",
    "check_resonances",
    "sample_rate",
    "TIME_GRID_TOL",
    "GAP_MIN_LINES",
    "LOW_COHERENCE",
    "MIN_SEGMENTS",
]

# Timestamps are taken as a uniform grid when every one lies within this
# fraction of a period of it: recorders print times with a few digits (the
# valve exports deviate by 3e-4 of a period, the actuator's by 5e-5).
TIME_GRID_TOL = 0.01
# A run of at least this many unused Welch lines between used ones is a gap.
GAP_MIN_LINES = 2
# Coherence below this is reported as low (the usual threshold for a usable
# H1 line; Bendat & Piersol's random error of |H| is ~10 % at 0.8 and 15 averages).
LOW_COHERENCE = 0.8
# With fewer Welch averages the coherence is biased towards 1 (identically 1
# for one segment) and says nothing.
MIN_SEGMENTS = 4


@dataclass
class FRF:
    """A frequency response on the lines a fit may use.

    Attributes
    ----------
    f_hz : ndarray
        Frequencies [Hz], strictly increasing, > 0.
    mag : ndarray
        Magnitude [output unit / input unit].
    phase_deg : ndarray
        Phase [deg], unwrapped.
    coherence : ndarray or None
        Magnitude-squared coherence [0, 1] (time-domain estimates only).
    resolution_hz : float or None
        Spacing of the estimate's line grid [Hz] when known (Welch: ``fs /
        nperseg``); lets :func:`find_gaps` tell a gap from the grid's spacing.
    """

    f_hz: np.ndarray
    mag: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray | None = None
    resolution_hz: float | None = None

    @property
    def w(self) -> np.ndarray:
        """Angular frequencies [rad/s]."""
        return 2.0 * np.pi * self.f_hz

    @property
    def h(self) -> np.ndarray:
        """Complex response :math:`A e^{j\\alpha}`."""
        return self.mag * np.exp(1j * np.deg2rad(self.phase_deg))


@dataclass
class Gap:
    """A band without usable data between two used lines.

    Attributes
    ----------
    lo_hz, hi_hz : float
        The used lines on either side [Hz]; the gap is the open interval between them.
    lines : int
        Unused lines inside (estimated from the spacing when the grid is not known).
    reason : str
        Why the lines inside are unused: ``"no input power"``, ``"low coherence"``,
        both joined by ``" and "``, or ``"no lines"`` (an FRF file without them).
    """

    lo_hz: float
    hi_hz: float
    lines: int
    reason: str

    def contains(self, f_hz: float) -> bool:
        """True if ``f_hz`` [Hz] lies strictly inside the gap."""
        return self.lo_hz < f_hz < self.hi_hz

    def to_dict(self) -> dict:
        return {"lo_hz": float(self.lo_hz), "hi_hz": float(self.hi_hz), "lines": int(self.lines),
                "reason": self.reason}

    def __str__(self) -> str:
        return f"{self.lo_hz:.4g}-{self.hi_hz:.4g} Hz ({self.reason})"


def sample_rate(t, rel_tol: float = TIME_GRID_TOL) -> float:
    """Sample rate [Hz] of a time column that is a uniform grid to within ``rel_tol`` of a period.

    The grid joins the first and last samples: period ``T = (t[-1] - t[0]) / (n - 1)``.
    Every ``t[k]`` must lie within ``rel_tol * T`` of ``t[0] + k T``; a missing or
    doubled sample, a pause or a second clock breaks that and is refused.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times [s], n >= 2.
    rel_tol : float
        Largest accepted deviation from the grid [periods] (default 1 %).

    Returns
    -------
    float
        ``1 / T`` [Hz].

    Raises
    ------
    ValueError
        One line saying which sample is off the grid and by how much.
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError("t: need at least 2 sample times")
    n = t.size
    period = (t[-1] - t[0]) / (n - 1)
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"t: the last time {t[-1]:.9g} s is not after the first {t[0]:.9g} s")
    dev = t - (t[0] + np.arange(n) * period)
    k = int(np.argmax(np.abs(dev)))
    if abs(dev[k]) > rel_tol * period:
        step = np.diff(t)
        med = float(np.median(step))
        jump = np.flatnonzero(np.abs(step - med) > 2 * rel_tol * med)
        if jump.size:  # a break: name the first one
            j = int(jump[0])
            raise ValueError(f"t: not uniformly sampled: from sample {j} to {j + 1} (t = {t[j]:.9g} -> "
                             f"{t[j + 1]:.9g} s) the step is {step[j]:.6g} s, the median step {med:.6g} s "
                             f"({jump.size} such steps): a gap, a pause or a changed rate; resample the "
                             f"recording to one rate or cut it at the break")
        raise ValueError(f"t: not uniformly sampled: sample {k} (t = {t[k]:.9g} s) is {dev[k] / period:+.3g} "
                         f"periods off the uniform grid through the first and last samples (accepted: "
                         f"{rel_tol:g} period): the rate drifts; resample the recording to one rate")
    return 1.0 / period


@dataclass
class FRFEstimate:
    """Every Welch line of an H1 estimate and whether it is used.

    Attributes
    ----------
    f_hz : ndarray
        Line frequencies in the band [Hz] (``k * resolution_hz``, k >= 1).
    h : ndarray of complex
        H1 at each line [output unit / input unit].
    coherence : ndarray
        Magnitude-squared coherence [0, 1].
    input_power : ndarray
        Input auto-spectrum relative to its in-band maximum [1].
    used : ndarray of bool
        Lines a fit may use (input power and coherence above their minimums).
    sample_rate_hz, resolution_hz : float
        Sample rate and line spacing [Hz].
    nperseg, segments : int
        Segment length [samples] and number of Welch averages.
    power_min, coherence_min : float
        The thresholds that decided ``used``.
    """

    f_hz: np.ndarray
    h: np.ndarray
    coherence: np.ndarray
    input_power: np.ndarray
    used: np.ndarray
    sample_rate_hz: float
    resolution_hz: float
    nperseg: int
    segments: int
    power_min: float
    coherence_min: float

    def frf(self) -> FRF:
        """The used lines as an :class:`FRF` (phase unwrapped over them)."""
        h = self.h[self.used]
        return FRF(self.f_hz[self.used], np.abs(h), np.rad2deg(np.unwrap(np.angle(h))),
                   self.coherence[self.used], self.resolution_hz)

    def gaps(self) -> list[Gap]:
        """Runs of at least :data:`GAP_MIN_LINES` unused lines between used ones, with the reason."""
        idx = np.flatnonzero(self.used)
        out = []
        for a, b in zip(idx[:-1], idx[1:]):
            if b - a - 1 < GAP_MIN_LINES:
                continue
            inside = slice(a + 1, b)
            weak = bool(np.any(self.input_power[inside] < self.power_min))
            incoherent = bool(np.any((self.input_power[inside] >= self.power_min)
                                     & (self.coherence[inside] < self.coherence_min)))
            reason = " and ".join(r for r, on in (("no input power", weak), ("low coherence", incoherent)) if on)
            out.append(Gap(float(self.f_hz[a]), float(self.f_hz[b]), int(b - a - 1), reason or "unusable"))
        return out

    def summary(self) -> dict:
        """Counts and bands for a report: lines, used, range, gaps, low-coherence lines."""
        f = self.frf()
        low = self.used & (self.coherence < LOW_COHERENCE)
        return {
            "lines": int(self.f_hz.size),
            "used_lines": int(np.count_nonzero(self.used)),
            "f_range_hz": [float(f.f_hz[0]), float(f.f_hz[-1])],
            "resolution_hz": float(self.resolution_hz),
            "sample_rate_hz": float(self.sample_rate_hz),
            "nperseg": int(self.nperseg),
            "segments": int(self.segments),
            "gaps": [g.to_dict() for g in self.gaps()],
            "low_coherence_lines": int(np.count_nonzero(low)),
            "coherence_median": float(np.median(self.coherence[self.used])),
        }

    def warnings(self) -> list[str]:
        """What a reader must know before trusting the estimate (one sentence each)."""
        out = []
        for g in self.gaps():
            out.append(f"no data {g.lo_hz:.4g}-{g.hi_hz:.4g} Hz: {g.lines} lines unused ({g.reason}); "
                       f"a fitted model is not constrained there")
        low = self.used & (self.coherence < LOW_COHERENCE)
        if np.any(low):
            fl = self.f_hz[low]
            out.append(f"coherence below {LOW_COHERENCE:g} on {int(np.count_nonzero(low))} of "
                       f"{int(np.count_nonzero(self.used))} used lines ({_bands(fl, self.resolution_hz)}): "
                       f"noise, nonlinearity, or leakage at a sharp resonance (a larger --nperseg resolves it); "
                       f"the magnitude there is biased low")
        if self.segments < MIN_SEGMENTS:
            out.append(f"only {self.segments} Welch average(s) of {self.nperseg} samples: the coherence is "
                       f"biased towards 1 and the estimate is noisy; use a smaller --nperseg")
        return out


def _bands(f: np.ndarray, res: float, limit: int = 4) -> str:
    """Frequencies on a grid of spacing ``res`` as contiguous bands: ``"10-30, 970 Hz"``."""
    if f.size == 0:
        return ""
    breaks = np.flatnonzero(np.diff(f) > 1.5 * res)
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks, [f.size - 1]))
    parts = [f"{f[a]:.4g}" if a == b else f"{f[a]:.4g}-{f[b]:.4g}" for a, b in zip(starts, ends)]
    more = f" and {len(parts) - limit} more bands" if len(parts) > limit else ""
    return ", ".join(parts[:limit]) + " Hz" + more


def estimate(t, u, y, *, nperseg: int | None = None, fmin: float | None = None,
             fmax: float | None = None, coherence_min: float = 0.0, power_min: float = 1e-4,
             detrend: str = "constant") -> FRFEstimate:
    """Welch H1 estimate of the response from ``u`` to ``y``, every line accounted for.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times [s]: a uniform grid by :func:`sample_rate`.
    u : array_like, shape (n,)
        Input (drive [V], or the hysteresis output [um] for a cascade).
    y : array_like, shape (n,)
        Output [um].
    nperseg : int, optional
        Segment length [samples], at most n. Default: with ``fmin``, the power of
        two at or above ``8 fs / fmin`` (eight lines below ``fmin``); else ``n // 8``
        (15 half-overlapping averages). The line spacing is ``fs / nperseg``.
    fmin, fmax : float, optional
        Band [Hz] (default: every line above 0 up to Nyquist).
    coherence_min : float
        Lines with a lower coherence are not used [0, 1] (default 0: all).
    power_min : float
        Lines whose input power is below this fraction of the in-band maximum
        are not used (not excited) [1].
    detrend : str
        Per-segment detrending passed to scipy (``"constant"``: the mean).

    Returns
    -------
    FRFEstimate

    Raises
    ------
    ValueError
        Arrays of different shapes or fewer than 16 samples, a time column that
        is not a uniform grid, an empty band, or fewer than 2 used lines.
    """
    from scipy import signal

    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if not (t.shape == u.shape == y.shape) or t.ndim != 1 or t.size < 16:
        raise ValueError("t, u, y must be 1-D of equal length >= 16")
    fs = sample_rate(t)
    if nperseg is None:
        if fmin:
            nperseg = 2 ** int(math.ceil(math.log2(8.0 * fs / fmin)))
        else:
            nperseg = max(16, u.size // 8)
    nperseg = int(min(nperseg, u.size))
    if nperseg < 4:
        raise ValueError(f"nperseg {nperseg}: need at least 4 samples per segment")
    f, puu = signal.welch(u, fs, nperseg=nperseg, detrend=detrend)
    _, pyy = signal.welch(y, fs, nperseg=nperseg, detrend=detrend)
    _, puy = signal.csd(u, y, fs, nperseg=nperseg, detrend=detrend)
    band = (f > 0) & (f >= (fmin or 0.0)) & (f <= (fmax or fs / 2))
    if not np.any(band):
        raise ValueError(f"no frequency line in the band {fmin or 0:g}-{fmax or fs / 2:g} Hz "
                         f"(line spacing {fs / nperseg:.4g} Hz)")
    f, puu, pyy, puy = f[band], puu[band], pyy[band], puy[band]
    pmax = puu.max()
    rel = puu / pmax if pmax > 0 else np.zeros_like(puu)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = puy / puu
        coh = np.abs(puy) ** 2 / (puu * pyy)
    coh = np.where(np.isfinite(coh), np.clip(coh, 0.0, 1.0), 0.0)
    used = (rel >= power_min) & np.isfinite(h) & (np.abs(h) > 0) & (coh >= coherence_min)
    h = np.where(np.isfinite(h), h, 0.0)
    if np.count_nonzero(used) < 2:
        raise ValueError(f"fewer than 2 usable frequency lines of {f.size} (input power >= {power_min:g} of "
                         f"its maximum, coherence >= {coherence_min:g}): excitation too weak or incoherent")
    noverlap = nperseg // 2
    segments = max(1, (u.size - noverlap) // (nperseg - noverlap))
    return FRFEstimate(f, h, coh, rel, used, fs, fs / nperseg, nperseg, segments, power_min, coherence_min)


def frf_from_time(t, u, y, *, nperseg: int | None = None, fmin: float | None = None,
                  fmax: float | None = None, coherence_min: float = 0.0,
                  power_min: float = 1e-4, detrend: str = "constant") -> FRF:
    """The used lines of :func:`estimate` (same parameters) as an :class:`FRF`.

    Returns
    -------
    FRF
        With unwrapped phase, coherence and ``resolution_hz``.
    """
    return estimate(t, u, y, nperseg=nperseg, fmin=fmin, fmax=fmax, coherence_min=coherence_min,
                    power_min=power_min, detrend=detrend).frf()


def find_gaps(frf: FRF) -> list[Gap]:
    """Bands without data between the lines of an FRF (e.g. read from a file).

    With ``frf.resolution_hz`` known, a step between neighbouring lines of more
    than ``GAP_MIN_LINES + 0.5`` line spacings is a gap (at least
    :data:`GAP_MIN_LINES` lines missing). Without it, the spacing is judged
    locally: a step more than 2.5 times the smaller of its neighbouring steps
    is a gap (a linear or logarithmic grid has none; a hole in either does).

    Parameters
    ----------
    frf : FRF

    Returns
    -------
    list of Gap
    """
    f = np.asarray(frf.f_hz, dtype=float)
    d = np.diff(f)
    out = []
    for k, step in enumerate(d):
        if frf.resolution_hz:
            res = float(frf.resolution_hz)
        else:
            near = [d[j] for j in (k - 1, k + 1) if 0 <= j < d.size]
            if not near:
                continue
            res = min(near)
        if step > (GAP_MIN_LINES + 0.5) * res:
            out.append(Gap(float(f[k]), float(f[k + 1]), int(round(step / res)) - 1, "no lines"))
    return out


def check_resonances(poles, frf: FRF, gaps: list[Gap] | None = None,
                     low_coherence: float = LOW_COHERENCE) -> list[dict]:
    """Which resonances of a fitted model the data support.

    A resonance is a complex pole pair (one entry per pair, the pole with
    positive imaginary part). Its natural frequency ``f_n = |p| / 2 pi`` [Hz]
    and damping ratio ``zeta = -Re p / |p|`` are checked against the data:

    - ``"outside the data"``: ``f_n`` below the first or above the last used line;
    - ``"in a gap"``: ``f_n`` inside a band without data (:class:`Gap`);
    - ``"low coherence"``: the used lines around it (the nearest on each side and
      any within its half-power band ``f_n (1 +- zeta)``) have a coherence below
      ``low_coherence``. The lines are there but biased (noise, nonlinearity, or
      leakage when the line spacing is not fine against the mode's bandwidth
      ``2 zeta f_n``): the resonance is flagged, its frequency and damping are
      uncertain, but it is not unsupported.

    Parameters
    ----------
    poles : array_like of complex
        Poles of the fitted model [rad/s].
    frf : FRF
        The data it was fitted to.
    gaps : list of Gap, optional
        Default :func:`find_gaps` of ``frf``.
    low_coherence : float
        Coherence threshold [0, 1].

    Returns
    -------
    list of dict
        Sorted by frequency: ``f_hz``, ``damping``, ``supported`` (False when
        outside the data or in a gap), ``flags`` (the short names above) and
        ``problems`` (one line each).
    """
    f = np.asarray(frf.f_hz, dtype=float)
    gaps = find_gaps(frf) if gaps is None else gaps
    out = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag <= 0:
            continue
        fn = abs(p) / (2 * np.pi)
        zeta = -p.real / abs(p)
        problems, flags = [], []
        if fn < f[0] or fn > f[-1]:
            flags.append("outside the data")
            problems.append(f"outside the data ({f[0]:.4g}-{f[-1]:.4g} Hz)")
        for g in gaps:
            if g.contains(fn):
                flags.append("in a gap")
                problems.append(f"in a gap without data {g}")
        if frf.coherence is not None and f[0] <= fn <= f[-1]:
            near = (f >= fn * (1 - abs(zeta))) & (f <= fn * (1 + abs(zeta)))
            below, above = np.flatnonzero(f <= fn), np.flatnonzero(f >= fn)
            if below.size:
                near[below[-1]] = True
            if above.size:
                near[above[0]] = True
            c = float(np.min(frf.coherence[near]))
            if c < low_coherence:
                flags.append("low coherence")
                problems.append(f"low coherence ({c:.2f} < {low_coherence:g}) at its lines: "
                                f"frequency and damping uncertain")
        out.append({"f_hz": float(fn), "damping": float(zeta),
                    "supported": not ({"outside the data", "in a gap"} & set(flags)),
                    "flags": flags, "problems": problems})
    return sorted(out, key=lambda r: r["f_hz"])
