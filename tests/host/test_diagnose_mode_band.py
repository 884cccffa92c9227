"""Where unmodeled_resonance is offered (run._mode_freqs): above the calibration's band and, round 14, above the
band the base states it identified its dynamics in (base_info.dynamics_band_hz)."""

import numpy as np
from scipy import signal as sps

from piezoctl.diagnose import run

DT = 1e-4
N = 60_000


class _Sig:
    def __init__(self, yb, y):
        self.yb, self.y = yb, y


class _Rec:
    def __init__(self, u):
        self.u, self.dt = u, DT


def _case(f0=600.0, zeta=0.02, seed=1):
    """A model output x (broadband), a measurement with a mode at ``f0`` the model lacks (a small residue on top of
    a unit gain), and a calibration whose drive is a 5 Hz sine."""
    rng = np.random.default_rng(seed)
    b, a = sps.butter(2, 2000.0, fs=1.0 / DT)
    x = sps.lfilter(b, a, rng.standard_normal(N))
    w = 2 * np.pi * f0
    bm, am = sps.bilinear([w * w], [1.0, 2 * zeta * w, w * w], fs=1.0 / DT)
    y = x + 0.05 * (sps.lfilter(bm, am, x) - x) + 0.01 * rng.standard_normal(N)
    t = np.arange(N) * DT
    cal = [_Rec(50.0 + 40.0 * np.sin(2 * np.pi * 5.0 * t))]
    base = {"dynamics": {"b": [1.0], "a": [1.0]}}
    return base, [_Sig(x, y)], [np.ones(N, bool)], cal


def test_mode_offered_above_the_calibration_band():
    base, sigs, valid, cal = _case()
    f = run._mode_freqs(base, sigs, valid, cal, [0], DT)
    assert f and abs(f[0] - 600.0) <= 18.0


def test_mode_not_offered_inside_the_band_the_base_identified_its_dynamics_in():
    base, sigs, valid, cal = _case()
    assert run._mode_freqs(base, sigs, valid, cal, [0], DT, dynamics_band_hz=1000.0) == []
    f = run._mode_freqs(base, sigs, valid, cal, [0], DT, dynamics_band_hz=300.0)
    assert f and abs(f[0] - 600.0) <= 18.0
