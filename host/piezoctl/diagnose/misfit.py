"""The base's misfit on histories it did not see, as the nuisance every candidate must exceed (round 9).

A term's held-out improvement on the recordings says that the term fits something the base does not; it
does not say that this something is an effect rather than the base's own error on a drive history the
calibration did not show (docs/diagnose.md, round 8: nulls named a rate dependence, a bandwidth, a sensor
curve, an offset, creep). What such an error looks like is measured on the calibration itself
(``ident.base._holdout_histories``): each quarter of every calibration recording left out in turn
of the plane's fit and predicted. What counts is its energy *beyond* the full fit's error on the same
samples: the generalization gap. An effect the calibration contains (a delay, creep) is in both and cancels;
what remains is what a history the fit did not see adds. That excess is split into three bands a term
can take:

- *level*: the mean over the held-out history (an unknown initial state, a misfit of the loop's centre);
- *slow*: the rest below ``1 / block_s`` (slower than the test's blocks: a misfit that follows the history
  for seconds);
- *fast*: the rest.

A candidate is credited with its held-out improvement less, per band, the part the misfit there could
explain: ``credited = dE - sum_b clip(dE_b, 0, M_b)`` (energies per sample), and its *credited ratio* ``sqrt(1 - credited / MSE_before)`` must
meet the same ``RATIO_MAX`` as its held-out ratio. An effect the base's misfit could explain comes out
``none``; the price is that an effect smaller than that misfit in the band where it acts is not named.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sig

from .significance import unique_labels

__all__ = ["BANDS", "split_bands", "band_energy", "base_misfit", "credited_ratio", "above_per_recording", "ratios_above",
           "ratios_where"]

BANDS = ("level", "slow", "fast")


def split_bands(r, dt: float, f_slow_hz: float) -> np.ndarray:
    """(3, n) components of a contiguous residual ``r`` [um]: its mean, the rest low-passed (zero phase,
    second order Butterworth) at ``f_slow_hz``, and what is left. They sum to ``r``."""
    r = np.asarray(r, float)
    out = np.zeros((3, r.size))
    if r.size == 0:
        return out
    out[0] = r.mean()
    d = r - out[0]
    if r.size > 64 and f_slow_hz < 0.4 / dt:
        sos = sig.butter(2, f_slow_hz, fs=1.0 / dt, output="sos")
        out[1] = sig.sosfiltfilt(sos, d)
    out[2] = d - out[1]
    return out


def band_energy(parts, rec, dt: float, f_slow_hz: float) -> np.ndarray:
    """Summed squared band components (3,) [um^2] of the residual ``parts`` (1-d, concatenated recordings
    labelled by ``rec``; each recording's samples contiguous)."""
    e = np.zeros(3)
    for i in unique_labels(rec):
        e += np.sum(split_bands(parts[rec == i], dt, f_slow_hz) ** 2, axis=1)
    return e


ABOVE_MIN_SAMPLES = 64   # a stretch this short or shorter is not filtered above the edge (zero-phase padding)


def _highpass_sos(dt: float, edge_hz: float) -> np.ndarray:
    """The fourth order Butterworth high-pass at ``edge_hz`` [Hz] for sample period ``dt`` [s] (second-order sections)."""
    return sig.butter(4, edge_hz, "highpass", fs=1.0 / dt, output="sos")


def _above(r, sos) -> np.ndarray:
    """``r`` high-passed by ``sos`` (zero phase; :func:`ratios_above`'s filter), zeros when too short to filter."""
    r = np.asarray(r, float)
    if r.size <= ABOVE_MIN_SAMPLES:
        return np.zeros_like(r)
    return sig.sosfiltfilt(sos, r)


def base_misfit(holdout: list, names: list, dt: float, f_slow_hz: float, edge_hz: float | None = None) -> dict | None:
    """The base's error on held-out calibration histories, pooled: per band its energy per sample
    ``mse_um2`` (the fast band less the noise), the noise, and per history its RMS and its bands. With
    ``edge_hz`` (round 16: the calibration's band) also ``above_um2``, the same excess above ``edge_hz``
    (what :func:`ratios_above` subtracts).

    Parameters
    ----------
    holdout : list of dict
        ``ident.base._holdout_histories``'s result.
    names : list of str
        The calibration recordings' names.
    dt : float
        Sample period [s].
    f_slow_hz : float
        The level/slow band's upper edge [Hz].

    Returns
    -------
    dict or None
        None when no history was scored.
    """
    tot, tot_in = np.zeros(3), np.zeros(3)
    n_tot, d2, n_d = 0, 0.0, 0
    up = 0.0   # excess energy above edge_hz
    edge_ok = edge_hz is not None and 0.0 < edge_hz < 0.45 / dt
    sos = _highpass_sos(dt, edge_hz) if edge_ok else None
    rows = []
    for h in holdout:
        r, m = np.asarray(h["resid"], float), np.asarray(h["scored"], bool)
        if np.sum(m) < 16:
            continue
        parts = split_bands(r, dt, f_slow_hz)
        e = np.sum(parts[:, m] ** 2, axis=1)
        e_in = np.sum(split_bands(h["resid_in"], dt, f_slow_hz)[:, m] ** 2, axis=1)
        n = int(np.sum(m))
        dd = np.diff(r)[m[1:] & m[:-1]]
        d2 += float(np.sum(dd ** 2))
        n_d += dd.size
        tot += e
        tot_in += e_in
        if edge_ok:
            up += float(np.sum(_above(r, sos)[m] ** 2) - np.sum(_above(h["resid_in"], sos)[m] ** 2))
        n_tot += n
        rows.append({"recording": names[h["recording"]], "samples": [int(h["start"]), int(h["stop"])],
                     "scored_fraction": float(np.mean(m)), "rms_um": float(np.sqrt(np.mean(r[m] ** 2))),
                     "rms_seen_um": float(np.sqrt(e_in.sum() / n)),
                     "level_um": float(parts[0, 0]), "slow_rms_um": float(np.sqrt(e[1] / n)),
                     "fast_rms_um": float(np.sqrt(e[2] / n))})
    if n_tot == 0:
        return None
    noise2 = 0.5 * d2 / max(n_d, 1)
    excess = np.maximum(tot - tot_in, 0.0) / n_tot
    return {"method": ("each quarter of every calibration recording left out of the plane's fit in turn, the "
                       "plane's knot values refitted on the rest (size and dynamics kept), the recordings simulated "
                       "and scored on the left-out quarter where its drive lies within the range the refit saw; "
                       "the misfit is the energy per sample beyond the full fit's on the same samples"),
            "slow_hz": f_slow_hz, "rms_um": float(np.sqrt(tot.sum() / n_tot)),
            "rms_seen_um": float(np.sqrt(tot_in.sum() / n_tot)), "noise_rms_um": float(np.sqrt(noise2)),
            "mse_um2": dict(zip(BANDS, map(float, excess))), "histories": rows,
            **({"above_hz": float(edge_hz), "above_um2": max(up, 0.0) / n_tot} if edge_ok else {})}


def credited_ratio(e_before, correction, rec, dt: float, misfit: dict | None) -> tuple:
    """(credited ratio, per band dict) of a candidate: its held-out improvement per band beyond the base's
    misfit energy there (module docstring). ``e_before``: the residual before the term (nested), ``correction``:
    the term's held-out predicted correction, both over the used samples, ``rec`` their recording labels.
    Without a misfit estimate the ratio is the plain held-out ratio."""
    n = max(e_before.size, 1)
    mse_b = float(np.sum(e_before ** 2)) / n
    if mse_b <= 0:
        return 1.0, {}
    f = misfit["slow_hz"] if misfit else 1.0
    eb = band_energy(e_before, rec, dt, f) / n
    ea = band_energy(e_before - correction, rec, dt, f) / n
    m = np.array([misfit["mse_um2"][b] for b in BANDS]) if misfit else np.zeros(3)
    gain = eb - ea
    # the whole improvement less, per band, the part of it the misfit there could explain (a band the term
    # makes worse counts against it in full)
    total = mse_b - float(np.sum((e_before - correction) ** 2)) / n
    credited = total - float(np.sum(np.clip(gain, 0.0, m)))
    ratio = float(np.sqrt(max(1.0 - credited / mse_b, 0.0)))
    return ratio, {b: {"improvement_um2": float(g), "misfit_um2": float(x)} for b, g, x in zip(BANDS, gain, m)}


def _one_band_credited(eb, ea, m) -> float:
    """The credited ratio of one band (the module's rule with a single band): mean energies per sample before and
    after the term ``eb`` > 0, ``ea``, and the base's misfit energy ``m`` there [um^2]."""
    credited = (eb - ea) - min(max(eb - ea, 0.0), m)
    return float(np.sqrt(max(1.0 - credited / eb, 0.0)))


def above_per_recording(e, rec, dt: float, edge_hz: float) -> tuple:
    """(``e`` high-passed at ``edge_hz`` per recording, mask of the samples filtered): :func:`ratios_above`'s
    filter (zero phase, fourth order Butterworth), recordings of at most ``ABOVE_MIN_SAMPLES`` left out.

    Parameters
    ----------
    e : ndarray
        A residual [um], each recording's samples contiguous.
    rec : ndarray of int
        Recording label of each sample.
    dt : float
        Sample period [s].
    edge_hz : float
        The band edge [Hz], below ``0.45 / dt``.

    Returns
    -------
    (ndarray, ndarray of bool)
        The high-passed residual [um] (zero where not filtered) and the filtered samples.
    """
    e = np.asarray(e, float)
    sos = _highpass_sos(dt, edge_hz)
    h, done = np.zeros_like(e), np.zeros(e.size, bool)
    for i in unique_labels(rec):
        m = rec == i
        if np.sum(m) > ABOVE_MIN_SAMPLES:
            h[m], done[m] = _above(e[m], sos), True
    return h, done


def ratios_above(e_before, correction, fold, rec, dt: float, edge_hz: float, misfit: dict | None) -> tuple:
    """(fold ratios, credited ratio) of a candidate on the residual above ``edge_hz`` (round 16).

    A term whose effect lies above the band the calibration identified the dynamics in (a mode offered above it)
    explains nothing below it; there the residual is the base's hysteresis and its slow misfit, which no such term
    can take and which says nothing about it. Its size is judged on the band where it acts: the held-out residual
    without and with the term, high-passed (zero phase, fourth order Butterworth) at ``edge_hz`` per recording.
    The credited ratio subtracts the base's misfit there from the improvement there, as :func:`credited_ratio`
    does per band: ``misfit["above_um2"]`` (the same excess on held-out calibration histories, filtered the same
    way) when it was measured at this edge or below it (round 17: taken as the bound of the excess above a higher
    edge, the mode's own), else the whole *fast* misfit (everything above ``1 / block_s``).

    Parameters
    ----------
    e_before, correction : ndarray
        The residual before the term (nested) and the term's held-out predicted correction [um], used samples.
    fold : ndarray of int
        Fold (0/1) of each sample; fold ratio f is scored on fold 1 - f, as in ``select._evaluate``.
    rec : ndarray of int
        Recording label of each sample (each recording's samples contiguous).
    dt : float
        Sample period [s].
    edge_hz : float
        The band edge [Hz].
    misfit : dict or None
        ``base_misfit``'s result.

    Returns
    -------
    (list of float, float)
        The two fold ratios and the credited ratio above ``edge_hz``; (None, None) when the edge is not below
        the Nyquist frequency or no recording is long enough to filter.
    """
    e_before = np.asarray(e_before, float)
    e_after = e_before - np.asarray(correction, float)
    if not 0.0 < edge_hz < 0.45 / dt:
        return None, None
    hb, done = above_per_recording(e_before, rec, dt, edge_hz)
    ha, _ = above_per_recording(e_after, rec, dt, edge_hz)
    if not np.any(done):
        return None, None
    frs = []
    for f in (1, 0):
        t = done & (fold == f)
        eb = float(np.sum(hb[t] ** 2))
        frs.append(float(np.sqrt(np.sum(ha[t] ** 2) / eb)) if eb > 0 else 1.0)
    n = max(int(np.sum(done)), 1)
    eb, ea = float(np.sum(hb[done] ** 2)) / n, float(np.sum(ha[done] ** 2)) / n
    if eb <= 0:
        return frs, 1.0
    if misfit and misfit.get("above_hz") is not None and misfit["above_hz"] <= edge_hz:
        # round 17: measured at this edge or below it (the mode's own edge lies above the calibration's)
        m_fast = float(misfit["above_um2"])
    else:
        m_fast = float(misfit["mse_um2"]["fast"]) if misfit else 0.0
    return frs, _one_band_credited(eb, ea, m_fast)


def ratios_where(e_before, correction, fold, where, misfit: dict | None) -> tuple:
    """(fold ratios, credited ratio) of a candidate on the samples ``where`` alone (round 17).

    A term that acts only where the drive left the calibrated range (the asymmetric term: an extra beyond a knee
    at or beyond the calibrated edge) explains nothing elsewhere; there the residual is the base's misfit on the
    in-range histories, which no such term can take and which says nothing about it. Its size is judged on the
    samples where it can act, as :func:`ratios_above` judges a mode on the band where it acts. The credited ratio
    subtracts the base's whole misfit energy per sample (every band of ``misfit["mse_um2"]``) from the
    improvement there.

    Parameters
    ----------
    e_before, correction : ndarray
        The residual before the term (nested) and the term's held-out predicted correction [um], used samples.
    fold : ndarray of int
        Fold (0/1) of each sample; fold ratio f is scored on fold 1 - f, as in ``select._evaluate``.
    where : ndarray of bool
        The samples to judge on.
    misfit : dict or None
        ``base_misfit``'s result.

    Returns
    -------
    (list of float, float)
        The two fold ratios and the credited ratio on ``where``; (None, None) when a fold has no such sample.
    """
    e_before = np.asarray(e_before, float)
    e_after = e_before - np.asarray(correction, float)
    frs = []
    for f in (1, 0):
        t = where & (fold == f)
        eb = float(np.sum(e_before[t] ** 2))
        if eb <= 0:
            return None, None
        frs.append(float(np.sqrt(np.sum(e_after[t] ** 2) / eb)))
    n = int(np.sum(where))
    eb, ea = float(np.sum(e_before[where] ** 2)) / n, float(np.sum(e_after[where] ** 2)) / n
    m = float(sum(misfit["mse_um2"].values())) if misfit else 0.0
    return frs, _one_band_credited(eb, ea, m)
