"""Round 26: a drive-side term's refit of G keeps the current model's poles and zeros below the slow band's edge
(``ident.terms.slow_dynamics_kept``, used by ``_DriveTerm.refit_dynamics``). A delay or an amplifier's pole in
front of the stage changes nothing there; the ARX refit's near-cancelling slow pair moved the quasi-static gain
(round 25, s121-003: |G| 1.045 at 1 Hz)."""

import types

import numpy as np
from scipy import signal as sps

from piezoctl.ident.terms import TERMS, _is_slow, slow_dynamics_kept

DT = 1e-4          # 10 kHz
F_SLOW = 1.0       # [Hz]


def _gain(b, a, f_hz):
    _, h = sps.freqz(b, a, worN=np.atleast_1d(np.asarray(f_hz, float)), fs=1.0 / DT)
    return np.abs(h)


def _unit(b, a):
    b, a = np.asarray(b, float), np.asarray(a, float)
    return b * (np.sum(a) / np.sum(b)), a


def _tf(zeros, poles, lead=0):
    """(b, a) with these zeros and poles (in z), ``lead`` samples of pure delay, unit static gain."""
    b = np.concatenate([np.zeros(lead), np.atleast_1d(np.real(np.poly(zeros)))])
    return _unit(b, np.atleast_1d(np.real(np.poly(poles))))


FAST_POLE, FAST_ZERO = -0.44, -0.85   # s121-003's refit: its fast pole and zero


def test_a_near_cancelling_slow_pair_of_the_refit_gives_way_to_the_current_model_s_slow_gain():
    # the refit: s121-003's slow pair (gain step +4.5 % at about 0.4 Hz) beside a fast pole and zero
    b, a = _tf([0.99978, FAST_ZERO], [0.99977, FAST_POLE])
    assert _gain(b, a, 1.0)[0] > 1.04                     # the fault: the slow triangles read 4 % large
    b_now, a_now = _tf([0.5], [0.3])                      # the current G: flat below 1 kHz
    bn, an = slow_dynamics_kept(b, a, b_now, a_now, DT, F_SLOW)
    f = np.array([0.01, 0.1, 0.3, 1.0, 3.0])
    assert np.allclose(_gain(bn, an, f), _gain(b_now, a_now, f), atol=2e-3)
    # above the edge the refit's own dynamics stay: its fast pole and zero, at unit static gain
    bf, af = _tf([FAST_ZERO], [FAST_POLE])
    f = np.array([30.0, 300.0, 3000.0])
    assert np.allclose(_gain(bn, an, f), _gain(bf, af, f), rtol=1e-6)
    assert np.isclose(np.sum(bn) / np.sum(an), 1.0)
    assert len(an) == len(a)                              # the order is kept (a pole at 0 for the slow one)


def test_a_slow_lag_the_current_model_holds_is_kept_beside_the_refit_s_fast_dynamics():
    # a current G with a slow lag-lead of its own (10 % more gain above about 0.2 Hz), a refit without it
    b_now, a_now = _tf([0.99988], [0.99987])
    assert _gain(b_now, a_now, 3.0)[0] > 1.05
    b, a = _tf([FAST_ZERO], [FAST_POLE])
    bn, an = slow_dynamics_kept(b, a, b_now, a_now, DT, F_SLOW)
    f = np.array([0.01, 0.1, 0.3, 1.0])
    assert np.allclose(_gain(bn, an, f), _gain(b_now, a_now, f) * _gain(b, a, f), rtol=1e-4)
    assert len(an) == len(a) + 1                          # the current model's slow pole added


def test_without_slow_roots_the_refit_is_returned_unchanged():
    b, a = _tf([FAST_ZERO], [FAST_POLE, 0.85])            # 0.85: about 260 Hz
    b_now, a_now = _tf([0.2], [0.9])
    bn, an = slow_dynamics_kept(b, a, b_now, a_now, DT, F_SLOW)
    assert bn is b and an is a
    one = np.array([1.0])
    assert slow_dynamics_kept(one, one, one, one, DT, F_SLOW) == (one, one)   # a static G


def test_the_refit_s_pure_delay_samples_are_kept():
    b, a = _tf([0.99978, FAST_ZERO], [0.99977, FAST_POLE], lead=3)
    bn, an = slow_dynamics_kept(b, a, *_tf([], []), DT, F_SLOW)
    imp = sps.lfilter(bn, an, np.r_[1.0, np.zeros(20)])
    assert np.all(imp[:3] == 0.0) and imp[3] != 0.0


def test_roots_are_slow_by_their_frequency_below_the_edge():
    r = np.array([0.99977, 0.9999 + 0.0002j, 0.9, -0.5, 0.0, 13.5])
    assert list(_is_slow(r, DT, F_SLOW)) == [True, True, False, False, False, False]


def test_the_delay_s_refit_carries_the_current_model_s_slow_pole():
    # calibration: a stage whose G has a slow lag-lead (the current model holds it) behind an 8 samples' delay
    rng = np.random.default_rng(3)
    n = 60_000
    x = np.cumsum(rng.standard_normal(n)) * 0.01 + np.sin(2 * np.pi * 0.7 * np.arange(n) * DT)
    x = sps.lfilter(*sps.butter(2, 200.0, fs=1.0 / DT), x)
    g_true = _tf([0.9995, 0.3], [0.99945, 0.6])
    delayed = np.concatenate([np.full(8, x[0]), x[:-8]])
    y = sps.lfilter(g_true[0], g_true[1], delayed) + 1e-4 * rng.standard_normal(n)
    b_now, a_now = _tf([0.9995, 0.2], [0.99945, 0.7])     # the current model: the same slow pair
    cal = [types.SimpleNamespace(u=x, y=y, dt=DT)]
    ctx = types.SimpleNamespace(refit_cache={}, cal=cal, cal_h=[x], cal_k0=[0], dt=DT, misfit={"slow_hz": F_SLOW},
                                base={"hysteresis": {"offset": 0.0},
                                      "dynamics": {"b": list(b_now), "a": list(a_now)}})
    b, a = TERMS["delay"].refit_dynamics(ctx, 8)
    p = np.roots(a)
    slow = p[_is_slow(p, DT, F_SLOW)]
    assert slow.size == 1 and np.isclose(slow[0].real, 0.99945, rtol=0, atol=1e-9)
    assert np.isclose(np.sum(b) / np.sum(a), 1.0)
