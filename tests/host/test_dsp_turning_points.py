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


def test_stroke_half_excursion_is_the_amplitude_of_a_sine_and_noise_does_not_split_a_stroke():
    """Round 28: on a sine of amplitude 0.3 (with noise well inside the deadband) every sample after the first
    reversal lies on a stroke of half excursion 0.3; without the deadband the noise splits the strokes."""
    from piezoctl.dsp import stroke_half_excursion
    rng = np.random.default_rng(3)
    t = np.arange(20000) / 10000.0
    v = 0.1 + 0.3 * np.sin(2 * np.pi * 5 * t) + rng.normal(0, 0.001, t.size)
    a = stroke_half_excursion(v, 0.02)
    inner = (t > 0.06) & (t < 1.94)                   # between the first and the last reversal
    assert np.allclose(a[inner], 0.3, atol=0.01)
    assert np.median(stroke_half_excursion(v, 0.0)[inner]) < 0.05


def test_stroke_half_excursion_follows_strokes_of_different_sizes():
    """Strokes of 1, then 0.1, then 0.5 (half excursions 0.5, 0.05, 0.25) each carry their own half."""
    from piezoctl.dsp import stroke_half_excursion
    v = np.concatenate([np.linspace(0, 1, 101), np.linspace(1, 0.9, 11)[1:], np.linspace(0.9, 1.4, 51)[1:]])
    a = stroke_half_excursion(v, 0.02)
    assert np.allclose(a[:100], 0.5) and np.allclose(a[102:110], 0.05) and np.allclose(a[112:], 0.25)
    assert stroke_half_excursion(np.array([1.0]), 0.02).tolist() == [0.0]
