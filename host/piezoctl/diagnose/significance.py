"""The significance test of a candidate term (docs/diagnose.md, "Significance").

Data: the reveal recordings after their settling time, cut into time blocks (about
1 s, at least 6 per recording); even blocks form fold A, odd blocks fold B. A term
(its grid parameter *and* its coefficients) is fitted on one fold and predicts the
other; every sample is predicted exactly once by a fit that did not see it.

A term is *significant* when all hold:

1. the cross-validated held-out NRMSE falls to at most ``RATIO_MAX`` (0.9) of the
   model without the term, in each fold separately;
2. a one-sided t-test on the per-block reductions of the mean squared error
   (blocks are the units, so the residual's autocorrelation within a block does not
   inflate the sample size) gives p < ``P_MAX`` (0.001);
3. the Bayesian information criterion with an effective sample size (the number of
   samples divided by the residual's integrated autocorrelation time) decreases.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["RATIO_MAX", "P_MAX", "block_test", "effective_n", "bic_delta"]

RATIO_MAX = 0.9
P_MAX = 1e-3


def block_test(before: np.ndarray, after: np.ndarray, blocks: np.ndarray) -> tuple[float, float]:
    """One-sided t-test that the held-out squared error is smaller after the term.

    Parameters
    ----------
    before, after : ndarray
        Held-out residuals [um] without and with the term.
    blocks : ndarray of int
        Block id of each sample.

    Returns
    -------
    (t, p) : tuple of float
        t statistic of the mean per-block reduction of the MSE and its one-sided p value.
    """
    ids = np.unique(blocks)
    d = np.array([np.mean(before[blocks == b] ** 2) - np.mean(after[blocks == b] ** 2) for b in ids])
    if d.size < 3:
        return 0.0, 1.0
    sd = float(np.std(d, ddof=1))
    if sd == 0:
        return (np.inf, 0.0) if np.mean(d) > 0 else (0.0, 1.0)
    t = float(np.mean(d) / (sd / np.sqrt(d.size)))
    return t, float(stats.t.sf(t, d.size - 1))


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
