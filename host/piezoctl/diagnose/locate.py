"""Locating a mismatch: where the residual (measured - simulated) lives.

Per recording and time window, frequency band, drive amplitude, drive rate, direction
and other-axis motion; plus the whiteness and input-independence tests MATLAB's
``resid`` does (here on the residual decimated to 1 kHz at most).
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sig

__all__ = ["locate", "where_of", "peak_frequencies", "binned_rms", "residual_autocorrelation",
           "drive_discontinuities", "discontinuities_doc", "JUMP_NEIGHBOURS", "JUMP_FACTOR", "JUMP_SPAN_FRACTION"]

# A drive discontinuity (drive_discontinuities): a sample-to-sample change at least JUMP_FACTOR times the
# largest change among the JUMP_NEIGHBOURS changes on either side, and at least JUMP_SPAN_FRACTION of the
# recording's drive span. A sampled sine or triangle changes by similar amounts from sample to sample; a
# step, a recorder's reset or a chattering output does not.
JUMP_NEIGHBOURS = 5
JUMP_FACTOR = 4.0
JUMP_SPAN_FRACTION = 0.05
JUMPS_LISTED = 10       # per file, the largest, in time order


def binned_rms(x: np.ndarray, e: np.ndarray, n_bins: int = 8) -> dict:
    """RMS of ``e`` in quantile bins of ``x``: ``{"edges": [...], "rms": [...]}``."""
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 2:
        return {"edges": [float(x.min()), float(x.max())], "rms": [float(np.sqrt(np.mean(e ** 2)))]}
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    rms = [float(np.sqrt(np.mean(e[idx == k] ** 2))) if np.any(idx == k) else 0.0 for k in range(edges.size - 1)]
    return {"edges": [float(v) for v in edges], "rms": rms}


def _windows(t, e, n_top=3):
    n = e.size
    w = max(16, n // 20)
    k = n // w
    if k < 2:
        return []
    rms = np.sqrt(np.mean(e[: k * w].reshape(k, w) ** 2, axis=1))
    med = float(np.median(rms))
    order = np.argsort(rms)[::-1][:n_top]
    return [{"t0_s": float(t[i * w]), "t1_s": float(t[min((i + 1) * w, n - 1)]), "rms_um": float(rms[i]),
             "x_median": float(rms[i] / med) if med > 0 else float("inf")} for i in sorted(order)]


def _bands(e, dt, n_top=2):
    fs = 1.0 / dt
    f, p = sig.welch(e, fs=fs, nperseg=min(e.size, 8192))
    edges = [0.0, 1.0, 10.0, 100.0, 1000.0, fs / 2]
    edges = sorted(set(x for x in edges if x <= fs / 2))
    out = []
    tot = float(np.sum(p)) or 1.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (f >= lo) & (f < hi)
        out.append({"f_lo_hz": lo, "f_hi_hz": hi, "share": float(np.sum(p[m]) / tot)})
    out.sort(key=lambda b: -b["share"])
    return out[:n_top]


def peak_frequencies(es, dt, f_min: float = 80.0, n_peaks: int = 3) -> list[float]:
    """Frequencies [Hz] of narrow peaks of the residual spectrum above ``f_min``."""
    fs = 1.0 / dt
    long_enough = [e for e in es if e.size >= 256]
    if not long_enough:
        return []
    # one segment length for all: a recording shorter than 4096 samples would give another frequency grid
    nper = min(4096, min(e.size for e in long_enough))
    f = None
    ps = []
    for e in long_enough:
        f, p = sig.welch(e, fs=fs, nperseg=nper)
        ps.append(p)
    p = np.mean(ps, axis=0)
    m = (f > f_min) & (f < 0.45 * fs)
    if np.sum(m) < 8:
        return []
    lp = np.log(p[m] + 1e-30)
    base = sig.medfilt(lp, 151)  # wide: a damped mode (zeta 0.02 at 1.5 kHz) is 60 Hz = 25 bins wide
    pk, props = sig.find_peaks(lp - base, height=np.log(10.0))
    if pk.size == 0:
        return []
    # ranked by the excess power around the peak (a damped ring is broad; harmonic lines are tall but thin)
    ex = np.maximum(p[m] - np.exp(base), 0.0)
    energy = np.array([np.sum(ex[max(i - 12, 0): i + 13]) for i in pk])
    best = pk[np.argsort(energy)[::-1][:n_peaks]]
    return [float(f[m][i]) for i in best]


def where_of(sigs, contribs, dt) -> dict:
    """Where a fitted contribution acts: recordings, time windows, band, amplitude and rate bins."""
    energy = [float(np.sum(c ** 2)) for c in contribs]
    tot = sum(energy) or 1.0
    recs = sorted(({"recording": s.name, "share": e / tot} for s, e in zip(sigs, energy)),
                  key=lambda d: -d["share"])
    i = int(np.argmax(energy))
    s, c = sigs[i], contribs[i]
    amp = binned_rms(s.u, c, 5)
    rate = binned_rms(np.abs(np.gradient(s.u, dt)), c, 5)
    ka, kr = int(np.argmax(amp["rms"])), int(np.argmax(rate["rms"]))
    return {"recordings": [dict(r, share=round(r["share"], 3)) for r in recs if r["share"] > 0.01],
            "time_windows": [dict(w, recording=s.name) for w in _windows(s.t, c, 3)],
            "frequency_bands": _bands(c, dt, 2),
            "amplitude_v": [amp["edges"][ka], amp["edges"][ka + 1]],
            "rate_v_per_s": [rate["edges"][kr], rate["edges"][kr + 1]]}


def residual_autocorrelation(r: np.ndarray, dt: float, max_lag: int = 25, max_n: int = 20000):
    """Normalized autocorrelation of a residual decimated to at most 1 kHz, and its 99 % band.

    Parameters
    ----------
    r : ndarray
        Residual [um] at sample period ``dt`` [s].
    max_lag : int
        Lags 0..max_lag of the decimated residual.
    max_n : int
        At most this many decimated samples enter the correlation.

    Returns
    -------
    (lag_s, ac, bound) or None
        Lags [s], autocorrelation at those lags (``ac[0] = 1``), and the 99 % band ``2.58 / sqrt(n)`` of a
        white residual of ``n`` decimated samples; None when fewer than 64 remain.
    """
    step = max(1, int(round(1e-3 / dt)))
    rd = np.asarray(r)[::step]
    n = rd.size
    if n < 64:
        return None
    m = min(n, max_n)
    rr = rd - rd.mean()
    x = rr[:m]
    # lags 0..max_lag only, one dot product each: the same floats as those lags of np.correlate(x, x, "full"),
    # which computed all 2m - 1 (s0-017: 1.5 s of 71 s under the profiler for three calls)
    ac = np.array([np.dot(x[k:], x[:m - k]) for k in range(min(max_lag + 1, m))])
    ac = ac / (ac[0] or 1.0)
    return np.arange(ac.size) * step * dt, ac, 2.58 / np.sqrt(n)


def drive_discontinuities(t: np.ndarray, u: np.ndarray) -> list[dict]:
    """Jumps of the drive: changes much larger than the changes around them (see ``JUMP_FACTOR``).

    Parameters
    ----------
    t, u : ndarray
        Sample times [s] and drive [V] of one recording.

    Returns
    -------
    list of dict
        One per jump, in time order: ``sample`` (index of the sample after the jump), ``t_s``,
        ``u_before_v``, ``u_after_v``, ``jump_v`` and ``where`` ("first sample", "last sample" or
        "inside").
    """
    u = np.asarray(u, dtype=float)
    if u.size < 3:
        return []
    d = np.diff(u)
    a = np.abs(d)
    w = JUMP_NEIGHBOURS
    pad = np.concatenate([np.zeros(w), a, np.zeros(w)])
    win = np.lib.stride_tricks.sliding_window_view(pad, 2 * w + 1).copy()
    win[:, w] = 0.0                       # the change itself is not its own neighbour
    local = win.max(axis=1)
    span = float(np.ptp(u))
    hit = np.nonzero((a >= JUMP_FACTOR * local) & (a >= JUMP_SPAN_FRACTION * span) & (a > 0))[0]
    n = u.size
    return [{"sample": int(k + 1), "t_s": float(t[k + 1]), "u_before_v": float(u[k]), "u_after_v": float(u[k + 1]),
             "jump_v": float(d[k]),
             "where": "first sample" if k == 0 else "last sample" if k + 1 == n - 1 else "inside"} for k in hit]


def discontinuities_doc(calibration, cal, recordings, recs) -> list[dict]:
    """diagnosis.json's ``drive_discontinuities``: per file with jumps, its role, count and largest jumps.

    Parameters
    ----------
    calibration, recordings : list of str
        The file paths.
    cal, recs : list of Recording
        The loaded recordings, in the same order.
    """
    out = []
    for role, paths, rs in (("calibration", calibration, cal), ("recording", recordings, recs)):
        for p, r in zip(paths, rs):
            jumps = drive_discontinuities(r.t, r.u)
            if not jumps:
                continue
            keep = sorted(sorted(jumps, key=lambda j: -abs(j["jump_v"]))[:JUMPS_LISTED], key=lambda j: j["sample"])
            out.append({"file": str(p), "role": role, "count": len(jumps), "jumps": keep})
    return out


def _xcorr_max(a, b, max_lag):
    a = (a - a.mean()) / (a.std() or 1.0)
    b = (b - b.mean()) / (b.std() or 1.0)
    n = a.size
    c = sig.correlate(a, b, mode="full", method="fft") / n
    mid = n - 1
    c = c[mid - max_lag: mid + max_lag + 1]
    return float(np.max(np.abs(c)))


def locate(sigs, residuals, dt) -> dict:
    """Residual analysis of the base model on every recording.

    Parameters
    ----------
    sigs : list of Signals
        Recordings with the base model's signals (settled part).
    residuals : list of ndarray
        Measured minus simulated [um], per recording.
    dt : float
        Sample period [s].

    Returns
    -------
    dict
        ``per_recording`` (NRMSE, RMS, mean, top windows, bands, direction means),
        ``amplitude``, ``rate``, ``other_axis`` binned RMS, and ``tests`` (whiteness:
        fraction of autocorrelations outside the 99 % band; input independence:
        largest cross-correlation with u, |du/dt|, u2 against its 99 % bound).
    """
    per = []
    for s, e in zip(sigs, residuals):
        du = np.gradient(s.u, dt)
        rising, falling = du > 0, du < 0
        span = float(np.ptp(s.y)) or 1.0
        per.append({"recording": s.name, "nrmse": float(np.sqrt(np.mean(e ** 2)) / span),
                    "rms_um": float(np.sqrt(np.mean(e ** 2))), "mean_um": float(np.mean(e)),
                    "windows": _windows(s.t, e), "bands": _bands(e, dt),
                    "mean_rising_um": float(np.mean(e[rising])) if rising.any() else 0.0,
                    "mean_falling_um": float(np.mean(e[falling])) if falling.any() else 0.0})
    u = np.concatenate([s.u for s in sigs])
    e = np.concatenate(residuals)
    rate = np.concatenate([np.abs(np.gradient(s.u, dt)) for s in sigs])
    out = {"per_recording": per, "amplitude": binned_rms(u, e), "rate": binned_rms(rate, e)}
    if any(s.u2 is not None for s in sigs):
        m2 = np.concatenate([np.abs(np.gradient(s.u2, dt)) if s.u2 is not None else np.zeros(s.u.size)
                             for s in sigs])
        moving = m2 > 1e-3 * (np.max(m2) or 1.0)
        out["other_axis"] = {"rms_moving_um": float(np.sqrt(np.mean(e[moving] ** 2))) if moving.any() else 0.0,
                             "rms_still_um": float(np.sqrt(np.mean(e[~moving] ** 2))) if (~moving).any() else 0.0}
    step = max(1, int(round(1e-3 / dt)))
    tests = {"whiteness_outside_99": [], "xcorr_u": [], "xcorr_rate": [], "xcorr_u2": [], "bound_99": []}
    for s, r in zip(sigs, residuals):
        acr = residual_autocorrelation(r, dt)
        if acr is None:
            continue
        _, ac, bound = acr
        rd = r[::step]
        tests["whiteness_outside_99"].append(float(np.mean(np.abs(ac[1:]) > bound)))
        tests["xcorr_u"].append(_xcorr_max(rd, s.u[::step], 25))
        tests["xcorr_rate"].append(_xcorr_max(rd, np.abs(np.gradient(s.u, dt))[::step], 25))
        if s.u2 is not None and np.ptp(s.u2) > 0:
            tests["xcorr_u2"].append(_xcorr_max(rd, s.u2[::step], 25))
        tests["bound_99"].append(float(bound))
    out["tests"] = tests
    return out
