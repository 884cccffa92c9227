"""``calibrate.coupling.periodic_rms``: the part of an error that repeats with
the other axis' period, corrected for the noise the period average keeps."""

import numpy as np
import pytest

from piezoctl.calibrate.coupling import periodic_rms


@pytest.mark.parametrize("amp_nm", [0.0, 1.0, 4.0, 20.0])
def test_the_periodic_part_is_recovered_under_noise_of_2_nm(amp_nm):
    rng = np.random.default_rng(int(amp_nm * 10) + 1)
    n, p, noise = 1000, 20, 0.002
    k = np.arange(n)
    # a triangle-like periodic error: fundamental + 3rd harmonic near a mode
    wave = np.sin(2 * np.pi * k / n) + 0.5 * np.sin(2 * np.pi * 3 * k / n + 1.0)
    wave *= amp_nm * 1e-3 / np.sqrt(np.mean(wave ** 2))
    est, noise_est = [], []
    for _ in range(40):
        e = np.tile(wave, p) + noise * rng.standard_normal(n * p)
        a, b = periodic_rms(e, n)
        est.append(a)
        noise_est.append(b)
    assert np.mean(noise_est) == pytest.approx(noise, rel=0.02)
    # the bias of the plain period mean would be noise / sqrt(p) = 0.45 nm: corrected, the estimate's
    # mean is within 0.15 nm of the truth at every size (the 0 nm case is clipped at 0, so biased up)
    assert abs(np.mean(est) - amp_nm * 1e-3) < 0.15e-3, (amp_nm, np.mean(est))
    plain = np.sqrt(np.mean(np.tile(wave, p).reshape(p, n).mean(axis=0) ** 2) + noise ** 2 / p)
    # at sizes near the noise the uncorrected period mean is off: the estimate is at least twice as close
    if amp_nm <= 1.0:
        assert abs(np.mean(est) - amp_nm * 1e-3) < 0.5 * abs(plain - amp_nm * 1e-3), (amp_nm, np.mean(est), plain)


def test_too_short_a_record_is_refused():
    with pytest.raises(ValueError, match="at least 2 periods"):
        periodic_rms(np.zeros(1500), 1000)
