"""Signature checks between candidates that explain the same data (docs/diagnose.md, "Discrimination").

The drive-side dynamics terms (delay, amplifier bandwidth, slew limit) all add phase lag, and with the base
dynamics refitted on a slow calibration they explain the reveal recordings almost equally well overall: the
base model's own error (hysteresis shape, noise) dominates what is left. What tells them apart is the shape
of fast motion, above the calibration's band: a delay shifts an edge and keeps it sharp (|H| = 1 at every
frequency), a bandwidth limit rounds it exponentially (|H| falls above fc), a slew limit turns it into a
ramp whose length grows with the step. So the candidates are compared on the *high-passed* residual of their
exact refined models (each fitted on one fold, scored on the other), block by block.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps
from scipy import stats

__all__ = ["calibration_band_hz", "highpassed", "discriminate_group", "ALPHA_DISC"]

ALPHA_DISC = 0.01


def calibration_band_hz(cal, k0s) -> float:
    """Frequency [Hz] below which 99 % of the calibration drive's rate (du/dt) energy lies."""
    f_all, p_all = [], []
    for r, k0 in zip(cal, k0s):
        du = np.diff(np.asarray(r.u, float)[k0:])
        if du.size < 16:
            continue
        p = np.abs(np.fft.rfft(du)) ** 2
        f_all.append(np.fft.rfftfreq(du.size, r.dt))
        p_all.append(p)
    if not f_all:
        return 0.0
    f = np.concatenate(f_all)
    p = np.concatenate(p_all)
    o = np.argsort(f)
    c = np.cumsum(p[o])
    return float(f[o][np.searchsorted(c, 0.99 * c[-1])])


def highpassed(ctx, ys, fc):
    """Residual (measured - model) of every recording high-passed at ``fc`` [Hz] (zero phase), settled samples
    concatenated."""
    sos = sps.butter(4, fc, "highpass", fs=1.0 / ctx.dt, output="sos")
    return np.concatenate([sps.sosfiltfilt(sos, s.y - y)[v] for s, y, v in zip(ctx.signals, ys, ctx.valid)])


def discriminate_group(cands, hp, fold_all, block_all, fc):
    """Order candidates of one group by their exact high-passed held-out residual.

    ``hp[i]``: the high-passed residual of candidate i's exact model, each sample predicted by the fold that did
    not see it. The candidate with the least energy wins when a one-sided t-test on the per-block log ratios
    ``log(E_other / E_best)`` (blocks of the selection samples) gives p < ``ALPHA_DISC`` against every other;
    otherwise the order is left to the overall held-out ratio and the evidence states the ambiguity.

    Returns
    -------
    (order, text) : (list of int, str)
    """
    used = fold_all >= 0
    ids, inv = np.unique(block_all[used], return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    en = [np.bincount(inv, h[used] ** 2) / cnt for h in hp]
    tot = [float(np.sum(e)) for e in en]
    best = int(np.argmin(tot))
    ps = []
    for i in range(len(hp)):
        if i == best:
            continue
        z = np.log((en[i] + 1e-30) / (en[best] + 1e-30))
        sd = float(np.std(z, ddof=1)) if z.size > 1 else 0.0
        if z.size < 4:
            ps.append(1.0)
        elif sd == 0:
            ps.append(0.0 if np.mean(z) > 0 else 1.0)
        else:
            ps.append(float(stats.t.sf(np.mean(z) / (sd / np.sqrt(z.size)), z.size - 1)))
    pmax = max(ps) if ps else 1.0
    names = [c.name for c in cands]
    rms = ", ".join(f"{n} {np.sqrt(t / len(ids)):.2e}" for n, t in zip(names, tot))
    if pmax < ALPHA_DISC:
        text = (f"Discrimination: above {fc:.0f} Hz (beyond the calibration's band) the exact held-out residual is "
                f"smallest with {names[best]} (block RMS^2 means: {rms}; paired block test p = {pmax:.1e}).")
        return [best] + [i for i in range(len(cands)) if i != best], text
    text = (f"Ambiguous: above {fc:.0f} Hz the candidates {', '.join(names)} leave similar residual "
            f"({rms}; p = {pmax:.1e}); ordered by the overall held-out error.")
    return list(range(len(cands))), text
