"""The significance test of a candidate term (docs/diagnose.md, "Significance").

Data: the reveal recordings after their settling time, cut into time blocks (about
1 s, at least 6 per recording); even blocks form fold A, odd blocks fold B. A term
(its grid parameter *and* its coefficients) is fitted on one fold and predicts the
other; every sample is predicted exactly once by a fit that did not see it.

A term is *significant* when all hold:

1. the cross-validated held-out NRMSE falls to at most ``RATIO_MAX`` (0.8) of the
   model without the term, in each fold separately;
2. on the *active* test units (where the term's held-out predicted correction, computed
   without the test fold's measurements, has at least ``ACTIVE_FRAC`` of its
   ``ACTIVE_PCT``-th percentile unit RMS) a one-sided t-test and a Wilcoxon signed-rank test (p = 2 x the
   smaller) on the per-unit log ratios ``log(MSE_before / MSE_after)`` gives p < ``ALPHA`` / m, m the number of
   candidates in the selection round (Bonferroni: family-wise error ``ALPHA`` = 1 % per round). Round 8: the
   units are parts of the blocks at least ``UNIT_TAUS`` correlation times of the residual's and the
   correction's energy long (:func:`test_units`), and both tests treat the blocks as clusters (a cluster-robust
   variance, the signed-rank test's variance inflated by the same design effect), so the residual's
   autocorrelation does not inflate the sample size while independent events (a step's ring) count each; the
   log ratio keeps a few large-error units (steps, corners) from swamping the test (see
   :func:`active_block_test`);
3. the Bayesian information criterion with an effective sample size (the number of
   samples divided by the residual's integrated autocorrelation time) decreases.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["fold_ratios", "RATIO_MAX", "WORSEN_MAX", "ALPHA", "ACTIVE_FRAC", "ACTIVE_PCT", "UNIT_TAUS", "UNIT_MIN_S", "active_block_test",
           "test_units", "energy_corr_time", "effective_n", "bic_delta"]

RATIO_MAX = 0.8
WORSEN_MAX = 1.5      # a named term whose exact refined model raises one recording's held-out error beyond this
                      # factor says so in its evidence (the model is wrong there)
ALPHA = 0.01          # family-wise error per selection round (Bonferroni over the candidates)
ACTIVE_PCT = 80.0     # reference block RMS of the correction: this percentile over the blocks (not the largest: a
                      # few blocks with spikes, e.g. steps of the other axis, must not silence the rest)
ACTIVE_FRAC = 0.1     # a block is "active" when the term's predicted correction there has at least this
                      # fraction of its largest block RMS
UNIT_TAUS = 4.0       # a test unit spans at least this many correlation times of the residual's energy (round 8)
UNIT_MIN_S = 0.05     # and at least this long [s]: a unit holds whole events (a step's ring, a corner)


def unique_labels(x, return_index: bool = False, return_inverse: bool = False, return_counts: bool = False):
    """``np.unique(x, ...)`` of a 1-d integer label array, the same arrays; by the runs of ``x`` when it is
    non-decreasing (block, unit and recording labels of concatenated recordings are: about 1 M samples each, a
    sort per call was 2.4 s of s0-017's 71 s under the profiler), else by ``np.unique``."""
    x = np.asarray(x)
    if x.ndim != 1 or x.size == 0 or x.dtype.kind not in "iu" or np.any(x[1:] < x[:-1]):
        return np.unique(x, return_index=return_index, return_inverse=return_inverse, return_counts=return_counts)
    start = np.concatenate([[0], np.flatnonzero(x[1:] != x[:-1]) + 1])
    out = [x[start]]
    if return_index:
        out.append(start)
    if return_inverse:
        step = np.zeros(x.size, np.intp)
        step[start[1:]] = 1
        out.append(np.cumsum(step))
    if return_counts:
        out.append(np.diff(np.append(start, x.size)))
    return out[0] if len(out) == 1 else tuple(out)


def effective_n(e: np.ndarray, max_lag: int = 2000) -> float:
    """Samples divided by the integrated autocorrelation time of ``e`` (at least 1).

    The autocorrelation of lags 0 .. L - 1 (L = min(max_lag, n - 1)) by one FFT of the residual zero-padded to
    m >= n + L - 1 samples: a circular correlation of that length has no wrapped terms at those lags. m is the
    next length of small prime factors (``scipy.fft.next_fast_len``), not the power of two >= 2 n: for the
    10^5 to 10^6-sample residuals of the diagnosis about half the length (the same lags to round-off)."""
    from scipy import fft as sfft
    e = np.asarray(e, float) - np.mean(e)
    n = e.size
    if n < 4 or np.var(e) == 0:
        return float(max(n, 1))
    lags = min(max_lag, n - 1)
    m = sfft.next_fast_len(n + lags, real=True)
    f = sfft.rfft(e, m)
    ac = sfft.irfft(f.real ** 2 + f.imag ** 2, m)[:lags]
    ac = ac / ac[0]
    neg = np.flatnonzero(ac < 0.05)
    cut = int(neg[0]) if neg.size else ac.size
    tau = 1.0 + 2.0 * float(np.sum(ac[1:cut]))
    return float(max(1.0, n / max(tau, 1.0)))


def energy_corr_time(e: np.ndarray, max_lag: int) -> float:
    """Integrated autocorrelation time [samples] of the residual's energy ``e**2`` (mean removed), at most
    about ``2 max_lag``; the per-unit MSEs of the test are averages of this energy, so units longer than a few
    of these times have nearly independent MSEs."""
    e2 = np.asarray(e, float) ** 2
    if e2.size < 4:
        return float(max(e2.size, 1))
    if np.var(e2) <= 1e-12 * (float(np.mean(e2)) ** 2 + 1e-300):
        return float(2 * max_lag)   # a constant (a level per recording): fully correlated, not white
    return float(e2.size / effective_n(e2, max_lag=max(int(max_lag), 2)))


def test_units(before: np.ndarray, blocks: np.ndarray, rec: np.ndarray, dt: float,
               correction: np.ndarray | None = None) -> np.ndarray:
    """The units of :func:`active_block_test`: each time block cut into equal parts no shorter than
    ``UNIT_TAUS`` correlation times of its recording's held-out residual energy (``before``), as many of the
    term's predicted correction's energy (``correction``, when given), and ``UNIT_MIN_S``.

    A slow misfit (an error that follows the history for seconds) keeps one unit per block, as before round 8; a
    residual made of short events (the ring after each step, a delay's error at each reversal) gives one unit per
    few events, so a few short, fast recordings hold enough independent units for the test to reach its level (9
    blocks, every one improved, cannot go below p = 2 x 2^-9 = 0.004 in the rank test).

    Parameters
    ----------
    before : ndarray
        Held-out residual [um] without the term (all used samples, recordings concatenated).
    blocks : ndarray of int
        Block id per sample (a block's samples are contiguous and within one recording).
    rec : ndarray of int
        Recording index per sample.
    dt : float
        Sample period [s].
    correction : ndarray, optional
        The term's held-out predicted correction [um]: a correction that follows the history for seconds (a
        loop's width, a level) keeps the units as long as it is, even where the residual is fast.

    Returns
    -------
    ndarray of int
        Unit id per sample (unique over all blocks).
    """
    blocks = np.asarray(blocks)
    units = np.zeros(blocks.size, int)
    ids, start, cnt = unique_labels(blocks, return_index=True, return_counts=True)
    rec_len = {}
    for r in unique_labels(rec):
        sel = rec == r
        nb_med = int(np.median(cnt[np.isin(ids, unique_labels(blocks[sel]))]))
        tau = energy_corr_time(before[sel], max_lag=nb_med)
        if correction is not None:
            tau = max(tau, energy_corr_time(correction[sel], max_lag=nb_med))
        rec_len[int(r)] = max(UNIT_TAUS * tau, UNIT_MIN_S / dt)
    nxt = 0
    for b0, n in zip(start, cnt):
        k = int(max(1, np.floor(n / rec_len[int(rec[b0])])))
        units[b0:b0 + n] = nxt + (np.arange(n) * k) // n
        nxt += k
    return units


def fold_ratios(before: np.ndarray, after: np.ndarray, fold: np.ndarray) -> list[float]:
    """Held-out RMS ratio after / before on each fold's test half: element f is over the rows of ``fold == 1 - f``
    (the fold fitted on fold f is tested on the other); 1.0 where ``before`` is zero there.

    ``before``, ``after``: residuals [um] on the rows; ``fold``: each row's fold (0 or 1)."""
    out = []
    for f in (0, 1):
        sel = fold == 1 - f
        sb = float(np.sum(before[sel] ** 2))
        out.append(float(np.sqrt(np.sum(after[sel] ** 2) / sb)) if sb > 0 else 1.0)
    return out


def bic_delta(sse_before: float, sse_after: float, n_eff: float, k: int) -> float:
    """Change of BIC = n_eff log(SSE) + k log(n_eff) when a k-parameter term is added (< 0: better)."""
    if sse_after <= 0 or sse_before <= 0:
        return -np.inf if sse_after < sse_before else np.inf
    return float(n_eff * np.log(sse_after / sse_before) + k * np.log(max(n_eff, 2.0)))


def _active_log_ratios(before, after, correction, groups):
    """(z, group index) of the active groups: ``z_g = log(MSE_before_g / MSE_after_g)`` where the correction's
    RMS in group g has at least ``ACTIVE_FRAC`` of its ``ACTIVE_PCT``-th percentile over the groups where it is
    not zero; None when the correction is zero everywhere."""
    ids, inv = unique_labels(groups, return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    mb = np.bincount(inv, before ** 2) / cnt
    ma = np.bincount(inv, after ** 2) / cnt
    mc = np.sqrt(np.bincount(inv, correction ** 2) / cnt)
    if mc.max() <= 0:
        return None
    nz = mc > 1e-9 * mc.max()   # groups where the term acts at all
    act = mc >= ACTIVE_FRAC * float(np.percentile(mc[nz], ACTIVE_PCT))
    tiny = 1e-30
    return np.log((mb[act] + tiny) / (ma[act] + tiny)), np.flatnonzero(act), inv


def _unit_test(before, after, correction, blocks, units):
    """The clustered test on the units (see :func:`active_block_test`): (t, p, n_active_units)."""
    ures = _active_log_ratios(before, after, correction, units)
    if ures is None:
        return 0.0, 1.0, 0
    zu, act, inv = ures
    first = np.zeros(inv.max() + 1, int)          # each unit's block: the block of its first sample
    first[inv[::-1]] = np.arange(inv.size)[::-1]
    gid, g_inv = unique_labels(np.asarray(blocks)[first[act]], return_inverse=True)
    n, g = int(zu.size), int(gid.size)
    if n < 4 or g < 2 or not np.any(zu != 0):
        return 0.0, 1.0, n
    m = float(np.mean(zu))
    var = float(np.sum(np.bincount(g_inv, zu - m) ** 2)) / n ** 2 * g / (g - 1)   # cluster-robust
    t = float(m / np.sqrt(var)) if var > 0 else (np.inf if m > 0 else 0.0)
    dof = g - 1
    # the signed-rank statistic on the units, its variance inflated by the same design effect (the
    # cluster-robust variance of the mean over the independent-units one, at least 1)
    s2 = float(np.var(zu, ddof=1))
    deff = max(1.0, var / (s2 / n)) if s2 > 0 else 1.0
    nz = zu[zu != 0]
    r = stats.rankdata(np.abs(nz))
    k = nz.size
    w = (float(np.sum(r[nz > 0])) - k * (k + 1) / 4.0) / np.sqrt(k * (k + 1) * (2 * k + 1) / 24.0)
    p_w = float(stats.norm.sf(w / np.sqrt(deff)))
    p_t = float(stats.t.sf(t, dof)) if np.isfinite(t) else (0.0 if t > 0 else 1.0)
    return t, min(1.0, 2.0 * min(p_t, p_w)), n


def active_block_test(before: np.ndarray, after: np.ndarray, correction: np.ndarray,
                      blocks: np.ndarray, units: np.ndarray | None = None) -> tuple[float, float, int]:
    """One-sided test that the term lowers the held-out error where it acts.

    The *active* blocks are those where the term's predicted correction (fitted on the
    other fold, evaluated from the test fold's inputs only, never its measurements) has
    an RMS of at least ``ACTIVE_FRAC`` of its ``ACTIVE_PCT``-th percentile block RMS over the blocks where
    it is not zero. On them, the per-block
    log ratio ``z_b = log(MSE_before_b / MSE_after_b)`` is scale free, so a few blocks
    with large errors (steps, corners) do not swamp the others; a one-sided t-test and a Wilcoxon signed-rank test
    (p = 2 x the smaller, Bonferroni) test z > 0. Blocks are the units, so the
    residual's autocorrelation within a block does not inflate the sample size.

    With ``units`` (round 8, :func:`test_units`: parts of the blocks a few correlation times of the residual's
    energy long) both tests run on the active units' log ratios, with the blocks as clusters: the t-test with a
    cluster-robust variance (the sandwich estimate with the small-sample factor G/(G-1), G - 1 degrees of
    freedom), the signed-rank test in its normal approximation with its variance inflated by the same design
    effect (that variance over the independent-units one, at least 1). Units of one block that improve together
    count as about one block; independent events within a block count each.

    Parameters
    ----------
    before, after : ndarray
        Held-out residuals [um] without and with the term.
    correction : ndarray
        The term's held-out predicted correction [um] (after - before prediction).
    blocks : ndarray of int
        Block id of each sample.
    units : ndarray of int, optional
        Unit id of each sample (within the blocks).

    Returns
    -------
    (t, p, n_active) : tuple
        t statistic, combined one-sided p value, number of active blocks (units when given).
    """
    if units is not None:
        # two valid tests, Bonferroni-combined: on the blocks (power where each block improves, e.g. a delay's
        # edges in every block while the units between edges change little) and on the units (power where the
        # evidence is many independent events in few blocks)
        tb, pb, nb = active_block_test(before, after, correction, blocks)
        tu, pu, nu = _unit_test(before, after, correction, blocks, units)
        return (tb, min(1.0, 2.0 * pb), nb) if pb <= pu else (tu, min(1.0, 2.0 * pu), nu)
    res = _active_log_ratios(before, after, correction, blocks)
    if res is None:
        return 0.0, 1.0, 0
    z = res[0]
    n = int(z.size)
    if n < 4 or not np.any(z != 0):
        return 0.0, 1.0, n
    # two one-sided tests, Bonferroni-combined (p = 2 min): the t-test (power with few active blocks: a
    # signed-rank test on n blocks cannot go below 2^-n) and the Wilcoxon signed-rank test (the z_b are heavy
    # tailed: a few blocks with steps or spikes improve by orders of magnitude, the rest a little, which
    # inflates the t-test's variance; the rank test only assumes the z_b symmetric about 0 when the term is
    # useless)
    p_w = float(stats.wilcoxon(z, alternative="greater").pvalue)
    sd = float(np.std(z, ddof=1))
    t = float(np.mean(z) / (sd / np.sqrt(n))) if sd > 0 else (np.inf if np.mean(z) > 0 else 0.0)
    dof = n - 1
    p_t = float(stats.t.sf(t, dof)) if np.isfinite(t) else (0.0 if t > 0 else 1.0)
    return t, min(1.0, 2.0 * min(p_t, p_w)), n
