"""The significance test of a candidate term (docs/diagnose.md, "Significance").

Data: the reveal recordings after their settling time, cut into time blocks (about
1 s, at least 6 per recording); even blocks form fold A, odd blocks fold B. A term
(its grid parameter *and* its coefficients) is fitted on one fold and predicts the
other; every sample is predicted exactly once by a fit that did not see it.

A term is *significant* when all hold:

1. the cross-validated held-out NRMSE falls to at most ``RATIO_MAX`` (0.8) of the
   model without the term, in each fold separately;
2. on the *active* blocks (where the term's held-out predicted correction, computed
   without the test fold's measurements, has at least ``ACTIVE_FRAC`` of its
   ``ACTIVE_PCT``-th percentile block RMS) a one-sided t-test and a Wilcoxon signed-rank test (p = 2 x the smaller) on the per-block log ratios
   ``log(MSE_before / MSE_after)`` gives p < ``ALPHA`` / m, m the number of candidates
   in the selection round (Bonferroni: family-wise error ``ALPHA`` = 1 % per round);
   blocks are the units, so the residual's autocorrelation within a block does not
   inflate the sample size, and the log ratio keeps a few large-error blocks (steps,
   corners) from swamping the test (see :func:`active_block_test`);
3. the Bayesian information criterion with an effective sample size (the number of
   samples divided by the residual's integrated autocorrelation time) decreases.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["RATIO_MAX", "WORSEN_MAX", "ALPHA", "ACTIVE_FRAC", "ACTIVE_PCT", "active_block_test", "effective_n", "bic_delta"]

RATIO_MAX = 0.8
WORSEN_MAX = 1.5      # a named term whose exact refined model raises one recording's held-out error beyond this
                      # factor says so in its evidence (the model is wrong there)
ALPHA = 0.01          # family-wise error per selection round (Bonferroni over the candidates)
ACTIVE_PCT = 80.0     # reference block RMS of the correction: this percentile over the blocks (not the largest: a
                      # few blocks with spikes, e.g. steps of the other axis, must not silence the rest)
ACTIVE_FRAC = 0.1     # a block is "active" when the term's predicted correction there has at least this
                      # fraction of its largest block RMS


def effective_n(e: np.ndarray, max_lag: int = 2000) -> float:
    """Samples divided by the integrated autocorrelation time of ``e`` (at least 1)."""
    e = np.asarray(e, float) - np.mean(e)
    n = e.size
    if n < 4 or np.var(e) == 0:
        return float(max(n, 1))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(e, m)
    ac = np.fft.irfft(f * np.conj(f), m)[: min(max_lag, n - 1)]
    ac = ac / ac[0]
    neg = np.flatnonzero(ac < 0.05)
    cut = int(neg[0]) if neg.size else ac.size
    tau = 1.0 + 2.0 * float(np.sum(ac[1:cut]))
    return float(max(1.0, n / max(tau, 1.0)))


def bic_delta(sse_before: float, sse_after: float, n_eff: float, k: int) -> float:
    """Change of BIC = n_eff log(SSE) + k log(n_eff) when a k-parameter term is added (< 0: better)."""
    if sse_after <= 0 or sse_before <= 0:
        return -np.inf if sse_after < sse_before else np.inf
    return float(n_eff * np.log(sse_after / sse_before) + k * np.log(max(n_eff, 2.0)))


def active_block_test(before: np.ndarray, after: np.ndarray, correction: np.ndarray,
                      blocks: np.ndarray) -> tuple[float, float, int]:
    """One-sided test that the term lowers the held-out error where it acts.

    The *active* blocks are those where the term's predicted correction (fitted on the
    other fold, evaluated from the test fold's inputs only, never its measurements) has
    an RMS of at least ``ACTIVE_FRAC`` of its ``ACTIVE_PCT``-th percentile block RMS over the blocks where
    it is not zero. On them, the per-block
    log ratio ``z_b = log(MSE_before_b / MSE_after_b)`` is scale free, so a few blocks
    with large errors (steps, corners) do not swamp the others; a one-sided t-test and a Wilcoxon signed-rank test
    (p = 2 x the smaller, Bonferroni) test z > 0. Blocks are the units, so the
    residual's autocorrelation within a block does not inflate the sample size.

    Parameters
    ----------
    before, after : ndarray
        Held-out residuals [um] without and with the term.
    correction : ndarray
        The term's held-out predicted correction [um] (after - before prediction).
    blocks : ndarray of int
        Block id of each sample.

    Returns
    -------
    (t, p, n_active) : tuple
        t statistic, combined one-sided p value, number of active blocks.
    """
    ids, inv = np.unique(blocks, return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    mb = np.bincount(inv, before ** 2) / cnt
    ma = np.bincount(inv, after ** 2) / cnt
    mc = np.sqrt(np.bincount(inv, correction ** 2) / cnt)
    if mc.max() <= 0:
        return 0.0, 1.0, 0
    nz = mc > 1e-9 * mc.max()   # blocks where the term acts at all
    act = mc >= ACTIVE_FRAC * float(np.percentile(mc[nz], ACTIVE_PCT))
    tiny = 1e-30
    z = np.log((mb[act] + tiny) / (ma[act] + tiny))
    if z.size < 4:
        return 0.0, 1.0, int(z.size)
    sd = float(np.std(z, ddof=1))
    t = float(np.mean(z) / (sd / np.sqrt(z.size))) if sd > 0 else (np.inf if np.mean(z) > 0 else 0.0)
    if not np.any(z != 0):
        return 0.0, 1.0, int(z.size)
    # two one-sided tests, Bonferroni-combined (p = 2 min): the t-test (power with few active blocks: a signed-rank
    # test on n blocks cannot go below 2^-n) and the Wilcoxon signed-rank test (the z_b are heavy tailed: a few
    # blocks with steps or spikes improve by orders of magnitude, the rest a little, which inflates the t-test's
    # variance; the rank test only assumes the z_b symmetric about 0 when the term is useless)
    p_t = float(stats.t.sf(t, z.size - 1)) if np.isfinite(t) else (0.0 if t > 0 else 1.0)
    p_w = float(stats.wilcoxon(z, alternative="greater").pvalue)
    return t, min(1.0, 2.0 * min(p_t, p_w)), int(z.size)
