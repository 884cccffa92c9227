"""Round 20: the blocks where the drive is beyond the calibrated range are shared between the two folds
(diagnose/select.make_masks)."""

import types

import numpy as np

from piezoctl.diagnose.run import OUT_MARGIN, excursions
from piezoctl.diagnose.select import FOLD_SHARE_MIN, make_masks

DT = 1e-3
EDGE_V = 120.0   # the calibrated drive range's upper edge


def _triangle(period_s, duration_s=12.0, lo=20.0, hi=150.0, delay_s=0.0):
    """A triangle from lo to hi [V] whose peaks lie at ``delay_s`` after odd multiples of half its period."""
    t = np.arange(int(duration_s / DT)) * DT
    ph = ((t - delay_s) / period_s) % 1.0
    return t, lo + (hi - lo) * (1.0 - np.abs(2.0 * ph - 1.0))


def _sig(t, u):
    return types.SimpleNamespace(t=t, u=u, dt=DT)


def _energy_per_fold(sigs, valid, fold):
    en = np.zeros(2)
    for s, v, f in zip(sigs, valid, fold):
        x = np.maximum(s.u - EDGE_V, 0.0)
        for k in (0, 1):
            en[k] += np.sum(x[v & (f == k)] ** 2)
    return en


def test_excursions_every_second_block_are_shared():
    # 12 blocks of 1 s after 0 s settling; a period of 2 s puts every peak (at 1.5, 3.5, ... s) and its excursion
    # beyond the edge in block 1, 3, 5...: alternate blocks give all of them to fold 1
    t, u = _triangle(2.0, delay_s=0.5)
    sigs = [_sig(t, u), _sig(*_triangle(0.7, lo=20.0, hi=110.0))]   # a second recording that stays in range
    valid, fold, _ = make_masks(sigs, 0.0, 1.0)
    before = _energy_per_fold(sigs, valid, fold)
    assert before.min() < 0.05 * before.max()   # the design's imbalance, as on s124-059
    excursion = [np.maximum(s.u - EDGE_V, 0.0) for s in sigs]
    valid2, fold2, block2 = make_masks(sigs, 0.0, 1.0, excursion)
    after = _energy_per_fold(sigs, valid2, fold2)
    assert after.min() > 0.8 * after.max()
    # the blocks and settled samples are those of the alternate design; the in-range recording's folds too
    _, _, block = make_masks(sigs, 0.0, 1.0)
    assert all(np.array_equal(a, b) for a, b in zip(block, block2))
    assert all(np.array_equal(a, b) for a, b in zip(valid, valid2))
    assert np.array_equal(fold[1], fold2[1])
    # the in-range blocks of the first recording still alternate between the folds
    b = block2[0][valid2[0]]
    f = fold2[0][valid2[0]]
    inside = np.array([not np.any(excursion[0][valid2[0]][b == k] > 0) for k in np.unique(b)])
    fb = np.array([f[b == k][0] for k in np.unique(b)])
    assert np.array_equal(fb[inside], np.arange(int(np.sum(inside))) % 2)


def test_without_excursions_the_folds_are_the_alternate_blocks():
    sigs = [_sig(*_triangle(1.3, lo=20.0, hi=110.0)), _sig(*_triangle(2.0, lo=30.0, hi=119.0))]
    old = make_masks(sigs, 0.5, 1.0)
    new = make_masks(sigs, 0.5, 1.0, [np.maximum(s.u - EDGE_V, 0.0) for s in sigs])
    for a, b in zip(old, new):
        assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_alternate_blocks_that_share_the_excursions_are_kept():
    # peaks every 1.5 s fall in blocks of both parities: the alternate blocks already share the excursion
    sigs = [_sig(*_triangle(1.5, delay_s=0.3))]
    excursion = [np.maximum(s.u - EDGE_V, 0.0) for s in sigs]
    old = make_masks(sigs, 0.0, 1.0)
    share = _energy_per_fold(sigs, old[0], old[1])
    assert share.min() >= FOLD_SHARE_MIN * share.max()
    new = make_masks(sigs, 0.0, 1.0, excursion)
    for a, b in zip(old, new):
        assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_a_rounding_beyond_the_edge_keeps_the_alternate_blocks():
    # the drive passes the calibrated edge by 1e-3 V (dev nulls s124-023, s124-032), every time in one fold
    t, u = _triangle(2.0, lo=20.0, hi=EDGE_V + 1e-3, delay_s=0.5)
    sigs = [_sig(t, u)]
    assert excursions(sigs, 10.0, EDGE_V) is None
    far = [_sig(t, np.where(u > EDGE_V, EDGE_V + 2 * OUT_MARGIN * (EDGE_V - 10.0), u))]
    x = excursions(far, 10.0, EDGE_V)
    assert x is not None and np.max(x[0]) > OUT_MARGIN * (EDGE_V - 10.0)
