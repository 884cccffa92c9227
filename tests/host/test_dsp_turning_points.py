"""dsp.turning_points: the reversals a drive's play, the base's path and the same-shape sweeps all read."""
import numpy as np

from piezoctl.dsp import turning_points


def test_a_triangle_turns_at_each_extreme_and_flat_steps_are_skipped():
    v = np.array([0, 1, 2, 2, 3, 2, 1, 1, 0, 1, 2], float)
    i = turning_points(v)
    # diff index 4 is the first step down after the top (v[4] = 3), 8 the first step up after the bottom (v[8] = 0)
    assert list(i) == [4, 8]
    assert list(v[i]) == [3.0, 0.0]


def test_a_monotone_or_constant_signal_has_none():
    assert turning_points(np.arange(10.0)).size == 0
    assert turning_points(np.zeros(5)).size == 0
    assert turning_points(np.array([1.0])).size == 0


def test_every_index_is_a_change_of_direction_and_none_is_missed():
    rng = np.random.default_rng(7)
    v = np.round(np.cumsum(rng.normal(size=500)))
    i = set(turning_points(v).tolist())
    d = np.sign(np.diff(v))
    last = 0.0
    for k, dk in enumerate(d):
        if dk == 0:
            continue
        assert (k in i) == (last != 0 and dk != last)
        last = dk
