"""Round 23: the residual's cycle means on a repeated drive (slow_signature.cycle_mean_test, drift_on_cycles).

A drift moves every cycle's mean on the clock; an offset is the same on every cycle; a loop converging on its orbit
(or a creep relaxing after the drive moved into the stretch) moves them by less and less. The figures of the
drift case are development s130-001's (docs/diagnose-rounds/round-23.md, "Round 23: drift and creep")."""

import types

import numpy as np

from piezoctl.diagnose import slow_signature as ss

FS = 2000.0   # [Hz]
PERIOD = 2.0  # [s]


def _triangle(n_cycles, period=PERIOD):
    t = np.arange(int(n_cycles * period * FS)) / FS
    ph = (t / period) % 1.0
    return t, 1.0 - 2.0 * np.abs(ph - 0.5)   # a maximum at every period's start, 0 .. 1


def _ctx(t, u, y, t_session=100.0):
    s = types.SimpleNamespace(t=t, u=u, y=y, index=0, t_session=t_session)
    return types.SimpleNamespace(signals=[s], valid=[t >= 0.5], offset_of=lambda i: 0, drift_t0=0.0)


def _test(e_of_t, n_cycles=16, noise=0.002, seed=0):
    t, u = _triangle(n_cycles)
    rng = np.random.default_rng(seed)
    y = 0.05 * np.sin(2 * np.pi * u) + e_of_t(t) + noise * rng.standard_normal(t.size)   # a misfit repeating per cycle
    ctx = _ctx(t, u, y)
    e = y[ctx.valid[0]]
    fold = (np.floor(t[ctx.valid[0]]) % 2).astype(int)   # ~1 s blocks, alternate folds
    return ss.cycle_mean_test([ctx, ctx], [e, e], fold)


def test_repeated_cycles_finds_a_repeated_triangle_and_refuses_a_walk():
    t, u = _triangle(10)
    k = ss.repeated_cycles(u)
    assert k is not None and k.size >= 9 and np.all(np.abs(np.diff(k) - PERIOD * FS) <= ss.CYCLE_PERIOD_TOL)
    walk = np.cumsum(np.random.default_rng(1).standard_normal(t.size))
    assert ss.repeated_cycles(walk) is None
    v = u.copy()
    v[t > 10] *= 0.5   # the same period, another amplitude: not one repeated cycle
    assert ss.repeated_cycles(v) is None


def test_a_drift_moves_the_cycle_means_and_persists():
    """s130-001's size: -0.17 um over 18 cycles of the long triangle (t = -109 on the residual)."""
    cy = _test(lambda t: -0.17 * t / t[-1])
    assert cy["t"] < -20 and cy["persists"] and ss.cycles_hold(cy, ss.ALPHA_SIGNATURE)
    assert abs(cy["slope_um_per_s"] * 32.0 + 0.17) < 0.02   # the line's slope is the drift's rate
    # a warm-up with a time constant of a minute still persists over the 32 s stretch
    cy = _test(lambda t: -0.3 * (1 - np.exp(-(t + 20) / 60.0)))
    assert ss.cycles_hold(cy, ss.ALPHA_SIGNATURE)


def test_an_offset_or_a_null_holds_at_about_the_tests_level():
    """A constant level on noise: the cycle means' t follows Student's t on their own scatter, so the test holds
    on about ``ALPHA_SIGNATURE`` of such recordings (0.13 expected of 40; at most 2 allowed)."""
    cys = [_test(lambda t: 0.4 + 0 * t, seed=seed) for seed in range(40)]
    assert sum(ss.cycles_hold(c, ss.ALPHA_SIGNATURE) for c in cys) <= 2
    assert np.median([abs(c["t"]) for c in cys]) < 1.5   # a t of 12 dof: median |t| 0.70


def test_a_converging_orbit_dies_out_and_is_refused():
    """A loop approaching its orbit (a Duhem law): +0.3 um over the first cycles, then geometrically less; its
    cycle means trend (t large) but the second half no longer moves: refused."""
    cy = _test(lambda t: 0.3 * (1 - 0.6 ** (t / PERIOD)), noise=0.0005)
    assert abs(cy["t"]) > 3 and not cy["persists"] and not ss.cycles_hold(cy, ss.ALPHA_SIGNATURE)


def test_a_change_within_the_noise_is_refused():
    """Null s121-045: -0.18 nm over 9 cycles at t = -6 against 2 nm of sensor noise; the same trend beyond it holds."""
    cy = _test(lambda t: -0.0004 * t / t[-1], noise=0.002, n_cycles=40)
    assert cy["p"] < ss.ALPHA_SIGNATURE and cy["persists"] and not cy["beyond_noise"]
    assert not ss.cycles_hold(cy, ss.ALPHA_SIGNATURE)
    cy = _test(lambda t: -0.004 * t / t[-1], noise=0.002, n_cycles=40)
    assert cy["beyond_noise"] and ss.cycles_hold(cy, ss.ALPHA_SIGNATURE)


def test_too_few_cycles_give_no_test():
    assert _test(lambda t: -0.1 * t, n_cycles=ss.CYCLE_MIN) is None


def _cand(folds, p, significant=False, veto=None, credited_only=False, dbic=-12.0):
    return types.SimpleNamespace(name="thermal_drift", significant=significant, veto=veto, fold_ratios=list(folds),
                                 credited=0.93, dbic=dbic, p=p, p_max=1.1e-3, discrimination=None,
                                 credited_only=credited_only)


def test_drift_on_cycles_lets_a_drift_that_lowers_each_fold_pass(monkeypatch):
    held = {"recordings": [0], "cycles": [18], "slopes_um_per_s": [-0.00884], "changes_um": [-0.170],
            "second_half_um_per_s": [-0.0085], "persists": True, "noise_um": [0.0074], "beyond_noise": True, "slope_um_per_s": -0.00884,
            "se_um_per_s": 0.00008, "t": -109.0, "dof": 16, "p": 2.1e-24}
    monkeypatch.setattr(ss, "cycle_mean_test", lambda *a: held)
    c = _cand([0.90, 0.87], 5.4e-3)   # s130-001's candidate
    ss.drift_on_cycles([c], None, None, None, lambda *a: None)
    assert c.significant and c.veto is None and "cycle means" in c.discrimination
    # a line that does not lower the error in each fold is not passed as it is: round 25 sizes it on the cycles
    # (test_slow_drift_r25.py); where the cycles cannot size it, it stays refused
    monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a: None)
    c = _cand([0.90, 1.02], 5.4e-3)
    ss.drift_on_cycles([c], [None, None], [None, None], None, lambda *a: None)
    assert not c.significant
    # a veto other than the credited ratio stands
    c = _cand([0.90, 0.87], 5.4e-3, veto="implausible")
    ss.drift_on_cycles([c], None, None, None, lambda *a: None)
    assert not c.significant and c.veto == "implausible"
    # dying out, or above the candidate's level: not
    for change in ({"persists": False}, {"p": 5e-3}, {"beyond_noise": False}):
        monkeypatch.setattr(ss, "cycle_mean_test", lambda *a, _c=change: {**held, **_c})
        c = _cand([0.90, 0.87], 5.4e-3)
        ss.drift_on_cycles([c], None, None, None, lambda *a: None)
        assert not c.significant
