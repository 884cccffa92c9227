"""Round 19 (delay): a drive-side term's nested test may correct the base's dynamics only above the band the base
identified them in (``Term.dynamics_nuisance_above_hz``, ``select.dynamics_nuisance``; off:
``terms.DRIVE_CORRECTIONS_ABOVE_BAND``)."""
from types import SimpleNamespace

import numpy as np

from piezoctl.diagnose.select import dynamics_nuisance
from piezoctl.ident import terms
from piezoctl.ident.terms import TERMS, Delay

DT = 1e-4   # [s]
EDGE = 100.0   # [Hz] the band the base identified its dynamics in


def _ctx(ys):
    """A context holding only what ``dynamics_nuisance`` reads: each recording's dynamic output ``ydyn`` [um]."""
    sigs = [SimpleNamespace(ydyn=y) for y in ys]
    valid = [np.arange(y.size) >= 500 for y in ys]   # the first 50 ms are not settled
    return SimpleNamespace(signals=sigs, valid=valid, dt=DT, dyn_nuisance=None, dyn_nuisance_above=None,
                           dynamics_band_hz=EDGE)


def _sine(f_hz, n=20000):
    return np.sin(2 * np.pi * f_hz * DT * np.arange(n))


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_drive_terms_correct_the_dynamics_above_the_band_only_when_switched_on(monkeypatch):
    ctx = _ctx([_sine(20.0)])
    for name in ("delay", "amplifier_bandwidth", "amplifier_slew_limit", "unmodeled_resonance",
                 "rate_dependent_hysteresis"):
        assert TERMS[name].dynamics_nuisance_above_hz(ctx) is None   # off: the whole band, as before round 19
    monkeypatch.setattr(terms, "DRIVE_CORRECTIONS_ABOVE_BAND", True)
    assert Delay().dynamics_nuisance_above_hz(ctx) == EDGE
    assert TERMS["amplifier_bandwidth"].dynamics_nuisance_above_hz(ctx) == EDGE
    assert TERMS["unmodeled_resonance"].dynamics_nuisance_above_hz(ctx) is None   # a mode's test is not changed
    assert TERMS["rate_dependent_hysteresis"].dynamics_nuisance_above_hz(ctx) is None


def test_the_corrections_above_the_band_vanish_below_it_and_stay_above_it():
    ctx = _ctx([_sine(20.0), _sine(600.0)])
    full = dynamics_nuisance(ctx)
    above = dynamics_nuisance(ctx, EDGE)
    n0 = int(np.sum(ctx.valid[0]))
    mid = slice(2000, n0 - 2000)   # away from the zero-phase filter's ends
    for j in (0, 1):
        assert _rms(above[:n0][mid, j]) < 0.01 * _rms(full[:n0][mid, j])            # 20 Hz: below the edge
        r = _rms(above[n0:][mid, j]) / _rms(full[n0:][mid, j])                        # 600 Hz: above it
        assert 0.95 < r < 1.05
    assert dynamics_nuisance(ctx) is full   # the whole band's columns are cached as before
    # an edge at or beyond the Nyquist frequency: the whole band
    assert np.array_equal(dynamics_nuisance(ctx, 0.5 / DT), full)


def test_a_delay_inside_the_band_is_not_absorbed_by_the_corrections_above_it():
    # a 0.5 ms delay on a 30 and 45 Hz drive: exp(-s d) = 1 - d s + d^2 s^2 / 2 - ..., so free c1 s + c2 s^2 over the
    # whole band take all but its third-order rest; the corrections above the band take the base's unknown G at
    # 600 Hz (here a first-order correction of the fast component) and leave the delay inside the band
    slow = _sine(30.0) + 0.3 * _sine(45.0)
    fast = 0.2 * _sine(600.0)
    d = 5
    lag = np.concatenate([np.zeros(d), slow[:-d]]) - slow   # the delay's residual inside the band
    g = 0.5 * np.diff(fast, prepend=fast[0])                 # G's misfit above it

    def left(ctx, e):
        v = ctx.valid[0]
        mid = slice(2000, int(np.sum(v)) - 2000)
        N = dynamics_nuisance(ctx, getattr(ctx, "edge", None))[mid]
        ev = e[v][mid]
        th, *_ = np.linalg.lstsq(N, ev, rcond=None)
        return ev - N @ th, ev

    rest, e = left(_ctx([slow]), lag)   # the whole band's corrections on the slow drive alone
    assert _rms(rest) < 0.05 * _rms(e)
    ctx = _ctx([slow + fast])
    ctx.edge = EDGE
    rest, e = left(ctx, lag + g)
    _, lag_v = left(_ctx([slow + fast]), lag)
    assert 0.95 < _rms(rest) / _rms(lag_v) < 1.05                        # the delay left whole, G's misfit taken
    assert float(rest @ lag_v) / (_rms(rest) * _rms(lag_v) * lag_v.size) > 0.99   # and the delay is what is left
