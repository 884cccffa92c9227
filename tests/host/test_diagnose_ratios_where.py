"""A term that acts only where the drive left the calibrated range is sized on those samples (round 17,
misfit.ratios_where, select.beyond_calibrated_mask): the base's misfit on the in-range histories neither helps nor
hides it, and the base's misfit energy is still subtracted from what it is credited with."""

import types

import numpy as np

from piezoctl.diagnose import misfit
from piezoctl.diagnose.select import BEYOND_GUARD_S, beyond_calibrated_mask
from piezoctl.ident.terms import TERMS

N = 20_000


def _case(seed=5):
    """A residual: a large in-range misfit (0.5 um RMS) everywhere plus, on the 10 % of samples beyond the edge, an
    extra of 0.3 um that the correction takes exactly."""
    rng = np.random.default_rng(seed)
    where = np.zeros(N, bool)
    for a in range(0, N, 2000):   # ten excursions, one per 2000 samples, alternating folds by block
        where[a + 800:a + 1000] = True
    extra = np.where(where, 0.3, 0.0)
    e = 0.5 * rng.standard_normal(N) + extra
    fold = ((np.arange(N) * 10) // N) % 2
    return e, extra, fold, where


def _misfit(um2):
    return {"slow_hz": 1.0, "mse_um2": {"level": 0.0, "slow": 0.0, "fast": um2}}


def test_the_extra_is_sized_where_it_acts_not_beside_the_in_range_misfit():
    e, extra, fold, where = _case()
    whole = [float(np.sqrt(np.sum((e - extra)[fold == f] ** 2) / np.sum(e[fold == f] ** 2))) for f in (1, 0)]
    assert min(whole) > 0.9           # beside the in-range misfit the extra fails any size gate
    fr, cr = misfit.ratios_where(e, extra, fold, where, _misfit(0.0))
    assert max(fr) < 0.9 and cr < 0.9
    assert max(fr) < min(whole) - 0.05


def test_the_misfit_is_still_subtracted():
    e, extra, fold, where = _case()
    gain = float(np.mean(e[where] ** 2) - np.mean((e - extra)[where] ** 2))
    assert gain > 0
    _, cr0 = misfit.ratios_where(e, extra, fold, where, _misfit(0.0))
    _, cr1 = misfit.ratios_where(e, extra, fold, where, _misfit(gain))
    assert cr0 < 0.9 and cr1 == 1.0    # a misfit as large as the gain leaves nothing credited


def test_a_fold_without_such_samples_gives_none():
    e, extra, fold, where = _case()
    fr, cr = misfit.ratios_where(e, extra, fold, where & (fold == 0), _misfit(0.0))
    assert fr is None and cr is None


def test_the_mask_holds_the_guard_after_the_drive_returns():
    dt = 1e-3
    u = np.concatenate([np.full(100, 50.0), np.full(20, 130.0), np.full(300, 50.0)])
    s = types.SimpleNamespace(u=u, dt=dt)
    ctx = types.SimpleNamespace(signals=[s], valid=[np.ones(u.size, bool)], cal_u_lo=0.0, cal_u_hi=120.0)
    m = beyond_calibrated_mask(ctx)
    g = int(round(BEYOND_GUARD_S / dt))
    assert not m[:100].any() and m[100:120].all()
    assert m[120:120 + g - 1].all() and not m[120 + g:].any()
    ctx.cal_u_hi = ctx.cal_u_lo   # no calibrated range known: nothing is beyond it
    assert not beyond_calibrated_mask(ctx).any()


def test_only_the_asymmetric_term_is_sized_beyond_the_edge():
    assert TERMS["asymmetric_hysteresis"].acts_beyond_calibration
    assert not any(t.acts_beyond_calibration for n, t in TERMS.items() if n != "asymmetric_hysteresis")
