"""Round 12: where the mode is offered (piezoctl.diagnose.signature.transfer_peaks). Synthetic model outputs x
and measurements y = x plus a mode the model lacks, plus noise: the residual transfer's peak must fall within the
mode grid's 3 % of the mode, also when the model's dynamics overshoot the measurement above their band (|T - 1|
dips at the mode there, |T| peaks); a residual that is noise alone offers nothing."""

import numpy as np
from scipy import signal as sps

from piezoctl.diagnose import signature as sig

DT = 1e-4          # 10 kHz
F_BAND = 300.0     # [Hz] the band "the calibration identified"
N = 60_000         # 6 s per recording


def _drive(seed, n=N):
    """A broadband model output [um]: white noise low-passed at 4 kHz plus a slow sine."""
    rng = np.random.default_rng(seed)
    b, a = sps.butter(2, 4000.0, fs=1.0 / DT)
    t = np.arange(n) * DT
    return 2.0 * np.sin(2 * np.pi * 2.0 * t) + sps.lfilter(b, a, rng.standard_normal(n))


def _mode(x, f0, zeta):
    """x through a unit-static-gain second-order mode at f0 (zero-order hold: no frequency warping)."""
    w = 2 * np.pi * f0
    b, a, _ = sps.cont2discrete(([w * w], [1.0, 2 * zeta * w, w * w]), DT, method="zoh")
    return sps.lfilter(np.ravel(b), np.ravel(a), x)


def _transfer(shape, seeds=(1, 2), noise=0.02):
    xs = [_drive(s) for s in seeds]
    ys = [shape(x) + noise * np.random.default_rng(s + 100).standard_normal(x.size) for x, s in zip(xs, seeds)]
    return sig.transfer(xs, ys, DT)


def test_a_missing_mode_is_offered_near_its_frequency():
    f0 = 1730.0
    tr = _transfer(lambda x: x + 0.05 * (_mode(x, f0, 0.02) - x))
    peaks = sig.transfer_peaks(tr, F_BAND)
    assert peaks, "no peak offered"
    assert abs(peaks[0] / f0 - 1.0) <= 0.03, peaks


def test_a_mode_on_a_transfer_the_model_overshoots_is_offered_by_its_magnitude_peak():
    # the measurement rolls off above 800 Hz where the model does not (|T| falls to ~0.2): |T - 1| is near 1
    # everywhere there and dips at the mode, |T| peaks at it (development case s110-006)
    f0 = 2900.0
    lp = sps.butter(2, 800.0, fs=1.0 / DT)
    tr = _transfer(lambda x: sps.lfilter(*lp, x) + 0.05 * (_mode(x, f0, 0.04) - x))
    peaks = sig.transfer_peaks(tr, F_BAND)
    assert any(abs(p / f0 - 1.0) <= 0.03 for p in peaks), peaks


def test_noise_alone_offers_no_mode():
    tr = _transfer(lambda x: x)
    assert sig.transfer_peaks(tr, F_BAND) == []


def test_nothing_without_a_transfer_or_bins_above_the_band():
    assert sig.transfer_peaks(None, F_BAND) == []
    tr = _transfer(lambda x: x + 0.05 * (_mode(x, 1730.0, 0.02) - x))
    assert sig.transfer_peaks(tr, 1e6) == []
