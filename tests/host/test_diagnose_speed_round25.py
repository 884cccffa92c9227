"""Round 25 (docs/diagnose-rounds/round-25.md, "Round 25: speed"): the base's filtered plane columns lose the
filters' subnormal tails (``dsp.flush_subnormal``), which made the refits' Gram matrices 10 to 50 times slower.
The base fit stays the same floats."""

import numpy as np
import pytest
from scipy import signal

from piezoctl import dsp
from piezoctl.ident import base as B
from piezoctl.io.recording import Recording
from piezoctl.models.hysteresis import hat_basis

from base_compare import assert_same_base

FS = 10_000.0
TINY = np.finfo(float).tiny


def test_flush_subnormal_zeroes_exactly_the_subnormals_in_place():
    x = np.array([[0.0, -0.0, TINY, -TINY, TINY / 2, -5e-324, 1e-300, np.inf, -np.inf, 1.0],
                  [np.nan, 3e-310, -3e-310, 2.0 * TINY, 1e-320, -1e-200, 0.5, -7.0, 4e-324, 1e308]])
    ref = x.copy()
    out = dsp.flush_subnormal(x)
    assert out is x                                  # in place
    sub = (ref != 0) & (np.abs(ref) < TINY)
    assert sub.sum() == 6          # TINY / 2, -5e-324, +-3e-310, 1e-320, 4e-324
    assert np.all(x[sub] == 0.0)
    keep = ~sub & ~np.isnan(ref)
    assert np.array_equal(x[keep], ref[keep]) and np.isnan(x[1, 0])


def test_a_filtered_hat_column_has_a_subnormal_tail_and_its_gram_is_unchanged_by_the_flush():
    # a hat that is nonzero only at the start, through a slow pole: the tail decays into the subnormal range
    # and stays there (a * x rounds back to x)
    rng = np.random.default_rng(0)
    v = np.concatenate([np.linspace(-1.0, 1.0, 2000), np.full(200_000, 1.0)])
    H = hat_basis(v, np.linspace(-1.0, 1.0, 7))[:, 1:]
    y = dsp.filt([0.01], [1.0, -0.99], H)
    assert np.count_nonzero((y != 0) & (np.abs(y) < TINY)) > 1000
    X = np.column_stack([y, rng.normal(size=v.size)])
    F = dsp.flush_subnormal(X.copy())
    assert not np.any((F != 0) & (np.abs(F) < TINY))
    G, Gf = X.T @ X, F.T @ F
    # sums holding a normal term are the same floats; the others (columns that are subnormal together) move by
    # less than the smallest normal number
    assert np.all((G == Gf) | (np.abs(G - Gf) < TINY))


def _calibration():
    """A decaying sine and FORC sweeps ending in a long dwell, through a Preisach-class law and a slow second-order
    mode: a base with dynamics, whose filtered hats have subnormal tails over the dwell."""
    from piezoctl.foreign.hysteresis import draw_law
    law = draw_law(np.random.default_rng(0), "preisach")
    b, a = signal.cont2discrete(([1.0], [1.0 / (2 * np.pi * 40.0) ** 2, 2 * 0.7 / (2 * np.pi * 40.0), 1.0]),
                                1.0 / FS)[:2]
    rng = np.random.default_rng(3)
    t = np.arange(int(6 * FS)) / FS
    cal_u = 75 + 72 * np.sin(2 * np.pi * 2 * t) * np.exp(-t / 3)
    fo = np.concatenate([np.linspace(3, 147, 4000)] + [np.concatenate([np.linspace(147, lv, 1500),
                                                                         np.linspace(lv, 147, 1500)])
                                                         for lv in np.linspace(10, 140, 10)])
    hold = np.concatenate([np.linspace(75, 140, 2000), np.full(int(4 * FS), 140.0)])   # a long dwell
    recs = []
    for u in (cal_u, np.concatenate([fo, hold])):
        y = dsp.filt(np.ravel(b), a, 20.0 * law((u - 75.0) / 75.0)) + rng.normal(0, 0.005, u.size)
        recs.append(Recording(t=np.arange(u.size) / FS, u=u, y=y))
    return recs


def test_the_base_fit_is_the_same_floats_with_and_without_the_flush(monkeypatch):
    recs = _calibration()
    flushed = []

    def counting(x):
        flushed.append(int(np.count_nonzero((x != 0) & (np.abs(x) < TINY))))
        return dsp.flush_subnormal(x)

    monkeypatch.setattr(B, "flush_subnormal", counting)
    new = B.fit_base(recs, holdout=True)
    assert new["base_info"]["dynamics_order"] > 0 and sum(flushed) > 0     # the flush had subnormals to remove
    monkeypatch.setattr(B, "flush_subnormal", lambda x: x)
    old = B.fit_base(recs, holdout=True)
    assert_same_base(new, old)                        # every parameter and held-out history, bit for bit
