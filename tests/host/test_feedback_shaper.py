"""The ZVD input shaper's spacing covers low first modes (the two-axis stage's
140 Hz needs 36 ticks at 10 kHz) up to the controller's limit, and the
registers refuse what the controller cannot hold."""

import numpy as np
import pytest

from piezoctl import interface
from piezoctl.calibrate.feedback import MAX_PREVIEW_TICKS, MAX_SHAPER_TICKS, zvd_shaper


@pytest.mark.parametrize("f_res, m_expected", [(970.0, 5), (140.0, 36), (80.0, 63)])
def test_zvd_spacing_is_half_the_damped_period(f_res, m_expected):
    zeta = 0.035
    m, taps = zvd_shaper(f_res, zeta, 10000.0)
    assert m == m_expected
    assert sum(taps) == 32768
    # a ZVD shaper has a double zero at the damped mode: what it passes there is tiny
    fd = f_res * np.sqrt(1 - zeta ** 2)
    z = np.exp(-2j * np.pi * fd * np.arange(3) * m / 10000.0)
    assert abs(np.dot(np.array(taps) / 32768.0, z)) < 0.02


def test_a_mode_below_the_limit_gets_no_shaper():
    m, taps = zvd_shaper(70.0, 0.035, 10000.0)   # 71 ticks > 64
    assert (m, taps) == (0, [32768, 0, 0])


def test_the_limits_are_the_registers_documented_ones():
    assert MAX_SHAPER_TICKS == 64 and MAX_PREVIEW_TICKS == 96
    docs = {p[0]: p[5] for p in interface.PARAMS}
    assert "1..64" in docs["shaper_ticks"] and "0..96" in docs["preview_ticks"]
