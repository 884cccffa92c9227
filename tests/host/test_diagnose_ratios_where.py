"""A term that acts only where the drive left the calibrated range is sized on those samples (round 17,
misfit.ratios_where, select.beyond_calibrated_mask; round 18: its block test there too, select.where_it_acts): the base's misfit on the in-range histories neither helps nor
hides it, and the base's misfit energy is still subtracted from what it is credited with."""

import types

import numpy as np

from piezoctl.diagnose import misfit
from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.select import BEYOND_GUARD_S, beyond_calibrated_mask, where_it_acts
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


def _knee_ctx(u, cal_hi=120.0):
    s = types.SimpleNamespace(u=np.asarray(u, float), dt=1e-3)
    return types.SimpleNamespace(signals=[s], valid=[np.ones(s.u.size, bool)], cal_u_lo=0.0, cal_u_hi=cal_hi)


def test_where_it_acts_needs_the_flag_and_a_knee_in_every_fold():
    u = np.concatenate([np.full(500, 50.0), np.full(100, 130.0), np.full(500, 50.0)])
    ctx, used = _knee_ctx(u), np.ones(u.size, bool)
    asym = TERMS["asymmetric_hysteresis"]
    w = where_it_acts(ctx, asym, [(1, 121.0), (1, 122.0, 3.0)], used)
    assert w is not None and np.array_equal(w, beyond_calibrated_mask(ctx))
    assert where_it_acts(ctx, asym, [(1, 121.0), None], used) is None     # a whole-stroke fit in one fold
    assert where_it_acts(ctx, TERMS["saturation"], [(1, 121.0)] * 2, used) is None
    assert where_it_acts(_knee_ctx(np.full(1100, 50.0)), asym, [(1, 121.0)] * 2, used) is None   # never beyond


def test_the_block_test_is_taken_where_the_knee_acts():
    """Round 18: ten blocks with an excursion beyond the edge, the correction taking its extra exactly, and ten
    in-range blocks where the nested refit's constant shifts the residual by 0.05 um (made worse): on every active
    unit the test fails; on the units where the term can act it passes."""
    rng = np.random.default_rng(3)
    nb, lb = 20, 1000
    u = np.full(nb * lb, 50.0)
    for b in range(0, nb, 2):
        u[b * lb + 400:b * lb + 600] = 130.0
    ctx, used = _knee_ctx(u), np.ones(u.size, bool)
    w = where_it_acts(ctx, TERMS["asymmetric_hysteresis"], [(1, 121.0)] * 2, used)
    e = 0.1 * rng.standard_normal(u.size) + np.where(w, 0.3, 0.0)
    corr = np.where(w, 0.3, -0.05)
    blocks, rec = np.arange(u.size) // lb, np.zeros(u.size, int)
    p_max = sg.ALPHA / 12

    def p_of(c):
        units = sg.test_units(e, blocks, rec, 1e-3, c)
        return sg.active_block_test(e, e - corr, c, blocks, units)[1]

    assert p_of(corr) > p_max
    assert p_of(np.where(w, corr, 0.0)) < p_max
