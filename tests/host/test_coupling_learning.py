"""The held axis' learning (``calibrate.ilc`` and ``calibrate.coupling``): the
loop measured with a flat multisine through the correction's own path, the
regularized learning filter near an antiresonance, the trials compared by what
repeats in them, and the trigger level on the other axis' drive."""

import numpy as np
import pytest

from piezoctl.calibrate import ilc
from piezoctl.calibrate.coupling import midlevel

FS = 10000.0


def two_mode_loop(f_hz):
    """A stand-in for the held axis' loop: the 140 Hz and 620 Hz modes of the two-axis
    stage (gains 0.98 and 0.02: an antiresonance near 540 Hz) and two ticks of delay."""
    s = 2j * np.pi * np.asarray(f_hz)
    t = np.zeros_like(s)
    for fm, zeta, g in ((140.0, 0.04, 0.98), (620.0, 0.03, 0.02)):
        w = 2 * np.pi * fm
        t = t + g * w * w / (s * s + 2 * zeta * w * s + w * w)
    return t * np.exp(-s * 2 / FS)


def periodic(T, x):
    return np.fft.irfft(T * np.fft.rfft(x), n=x.size)


def test_the_probe_is_flat_over_every_harmonic_up_to_its_band():
    n, f0 = 200, 50.0
    c = ilc.probe(n, f0, 1500.0, 0.1)
    assert np.sqrt(np.mean(c ** 2)) == pytest.approx(0.1, rel=1e-9)
    amp = np.abs(np.fft.rfft(c))[1:]
    f = np.arange(1, amp.size + 1) * f0
    inside = amp[f <= 1500.0]
    assert inside.size == 30 and np.allclose(inside, inside[0], rtol=1e-9)   # odd and even harmonics
    assert np.all(amp[f > 1500.0] < 1e-12 * inside[0])
    # Schroeder's phases: a crest factor far below the sum of the amplitudes
    assert np.max(np.abs(c)) < 0.35 * inside.size * inside[0] * 2 / n
    with pytest.raises(ValueError):
        ilc.probe(n, f0, 40.0, 0.1)


def test_the_loop_is_recovered_from_the_probe_under_noise():
    rng = np.random.default_rng(3)
    n, f0, p, noise = 200, 50.0, 100, 0.002
    T = two_mode_loop(np.arange(n // 2 + 1) * f0)
    c = ilc.probe(n, f0, 1500.0, 0.1)
    e = -periodic(T, c) + noise * rng.standard_normal((p, n))
    t_hat, sigma = ilc.loop_from_probe(e, c)
    k = np.arange(1, 31)
    err = np.abs(t_hat[k] - T[k])
    # the deviation the spread across periods gives is the actual one (within a factor 3 at every harmonic)
    assert np.all(err < 3.5 * sigma[k]) and np.median(err / sigma[k]) > 0.3
    assert np.all(np.isinf(sigma[31:])) and np.all(t_hat[31:] == 0)
    with pytest.raises(ValueError):
        ilc.loop_from_probe(e[:1], c)


def test_learning_through_the_measured_loop_removes_lines_beyond_the_old_band():
    """A disturbance with lines at 50 Hz and at 650 Hz (next to the 620 Hz mode, beyond 3 x 140 Hz):
    through the loop measured with noise and the regularized inverse, both go; with the band at 420 Hz,
    the 650 Hz line stays."""
    rng = np.random.default_rng(5)
    n, f0 = 200, 50.0
    fh = np.arange(n // 2 + 1) * f0
    T = two_mode_loop(fh)
    k = np.arange(n)
    d = 0.04 * np.sin(2 * np.pi * k / n) + 0.009 * np.sin(2 * np.pi * 13 * k / n + 0.5) \
        + 0.002 * np.sin(2 * np.pi * 11 * k / n)        # 550 Hz: next to the antiresonance
    c_probe = ilc.probe(n, f0, 1500.0, 0.1)
    t_hat, sigma = ilc.loop_from_probe(-periodic(T, c_probe) + 0.002 * rng.standard_normal((100, n)), c_probe)

    def run(f_cut):
        learner = ilc.ILC(n, f0, f_cut, alpha=0.5, loop=t_hat, loop_sigma=sigma, gain_max=100.0)
        res = ilc.learn(lambda c: -(d + periodic(T, c)), learner, 30)
        left = -(d + periodic(T, res["best"]))
        return res, np.abs(np.fft.rfft(left)) * 2 / n

    res, left = run(1500.0)
    assert res["refused"] == 0
    assert left[1] < 1e-3 * 0.04 and left[13] < 0.02 * 0.009
    assert left[11] < 0.5 * 0.002          # slower where the loop is small, but not the wrong way
    _, left_old_band = run(420.0)
    assert left_old_band[13] == pytest.approx(0.009, rel=0.01)


def test_a_loop_known_worse_than_its_own_size_is_not_learned_with_a_wrong_phase():
    """Where the measured loop's deviation exceeds its size, the regularized filter's gain is
    small: with an estimate 120 degrees off the line grows by 1 % a trial instead of the plain
    inverse's 32 % (what is left is the divergence guard's business, here switched off)."""
    n, f0 = 200, 50.0
    T = np.ones(n // 2 + 1, dtype=complex)
    T[5] = 0.02
    t_hat = T.copy()
    t_hat[5] = 0.02 * np.exp(2j * np.pi / 3)
    sigma = np.full(T.size, 1e-3)
    sigma[5] = 0.05
    k = np.arange(n)
    d = 0.01 * np.sin(2 * np.pi * 5 * k / n)
    plain = ilc.ILC(n, f0, 1000.0, loop=t_hat, gain_max=100.0, grow=1e9)   # no guard: the filter alone
    regular = ilc.ILC(n, f0, 1000.0, loop=t_hat, loop_sigma=sigma, gain_max=100.0, grow=1e9)
    for learner in (plain, regular):
        for _ in range(20):
            learner.update(-(d + periodic(T, learner.correction())))
    amp = lambda learner: np.abs(np.fft.rfft(-(d + periodic(T, learner.correction()))))[5] * 2 / n
    assert amp(regular) < 1.3 * 0.01
    assert amp(plain) > 100 * 0.01


def test_the_periodic_score_and_its_error():
    rng = np.random.default_rng(7)
    n, p, noise = 1000, 10, 0.002
    wave = 0.0003 * np.sqrt(2) * np.sin(2 * np.pi * 3 * np.arange(n) / n)   # 0.3 nm RMS
    scores, ses = [], []
    for _ in range(60):
        s, se = ilc.periodic_score(wave + noise * rng.standard_normal((p, n)))
        scores.append(s ** 2)
        ses.append(se)
    ms = np.array(scores)
    # unbiased in the square (the plain period mean would hold noise^2 / p = 0.4 nm^2 more)
    assert abs(ms.mean() - 0.0003 ** 2) < 3 * ms.std() / np.sqrt(ms.size)
    # the jackknife's standard error is the spread's or somewhat more (it is conservative: 1.3x here)
    assert ms.std() < np.mean(ses) < 1.6 * ms.std()
    with pytest.raises(ValueError):
        ilc.periodic_score(np.zeros((2, n)))


def test_noise_near_convergence_is_not_taken_for_divergence():
    """Trials whose score moves by its own noise are accepted; a real growth is refused."""
    n, f0 = 200, 50.0
    learner = ilc.ILC(n, f0, 1000.0, loop=np.ones(n // 2 + 1))
    e = np.zeros(n)
    assert learner.update(e, 0.09e-3, 0.025e-6)
    assert learner.update(e, 0.30e-3, 0.025e-6)     # 0.09 -> 0.30 nm: within 3 standard errors of the squares
    assert not learner.update(e, 0.60e-3, 0.025e-6)  # 0.36 nm^2 more: refused


def test_the_trigger_level_lies_halfway_between_two_samples_of_the_rising_edge():
    n = 200
    k = np.arange(n)
    tri = np.where(k < 100, -15000 + 300 * k, 15000 - 300 * (k - 100)).astype(float) + 37.0
    for shift in (0, 17, 150):
        u = np.roll(tri, shift)
        lv = midlevel(u, n)
        up = np.flatnonzero((u < lv) & (np.roll(u, -1) >= lv))
        assert up.size == 1
        # 150 LSB from both samples: noise of a few LSB cannot move the crossing by a tick
        assert min(lv - u[up[0]], u[(up[0] + 1) % n] - lv) >= 149
    with pytest.raises(ValueError):
        midlevel(tri[:50], n)
