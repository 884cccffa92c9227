"""Round 25: the drift sized on a repeated drive's cycles (slow_signature.drift_coef_on_cycles, drift_on_cycles).

A drift's line fitted on every block is pulled by the levels of recordings whose base misfit moves with their
history (development s133-001: the walk's residual rises +0.17 um while the drift moves -0.09 um through it); on a
repeated drive that misfit is the same at the same phase of every cycle, so the drift's rate is sized there
(docs/diagnose-rounds/round-25.md, "Round 25: slow effects")."""

import types

import numpy as np

from piezoctl.diagnose import slow_signature as ss
from test_slow_drift_r23 import FS, _triangle

PERIOD = 1.0  # [s]


def _ctx(recs):
    """recs: (t, u, y, t_session) per recording, all in one sensor-zero column other than the calibration's."""
    sig = [types.SimpleNamespace(t=t, u=u, y=y, index=i, t_session=ts) for i, (t, u, y, ts) in enumerate(recs)]
    return types.SimpleNamespace(
        signals=sig, valid=[s.t >= 0.5 for s in sig], offset_of=lambda i: 0, drift_t0=0.0, n_offset=lambda: 1,
        offset_columns=lambda s: np.ones((s.t.size, 1)))


RATE = -0.006   # [um/s] the drift's rate (s133-001's cycle means: -7.4 nm/s)
LEVEL = -0.44   # [um] the level it had reached at the session clock's 70 s


def _case(seed=0, walk_rise=0.17):
    """A repeated triangle from 70 s and a walk from 90 s on the session clock, a drift of ``RATE`` through both;
    the triangle's misfit repeats per cycle, the walk's misfit rises by ``walk_rise`` um against the drift."""
    rng = np.random.default_rng(seed)
    t1, u1 = _triangle(16, PERIOD)
    drift = lambda t, ts: LEVEL + RATE * (t + ts - 70.0)   # noqa: E731
    y1 = 0.05 * np.sin(2 * np.pi * u1) + drift(t1, 70.0) + 0.003 * rng.standard_normal(t1.size)
    t2 = np.arange(int(14 * FS)) / FS
    u2 = np.cumsum(rng.standard_normal(t2.size))
    u2 = (u2 - u2.min()) / np.ptp(u2)
    y2 = walk_rise * t2 / t2[-1] + drift(t2, 90.0) + 0.003 * rng.standard_normal(t2.size)
    ctx = _ctx([(t1, u1, y1, 70.0), (t2, u2, y2, 90.0)])
    e = np.concatenate([s.y[v] for s, v in zip(ctx.signals, ctx.valid)])
    tt = np.concatenate([s.t[v] for s, v in zip(ctx.signals, ctx.valid)])
    fold = (np.floor(tt) % 2).astype(int)   # ~1 s blocks, alternate folds
    return ctx, e, fold


def test_the_rate_is_sized_on_the_cycles_whatever_the_walk_does():
    for rise in (0.0, 0.17, -0.3):
        ctx, e, fold = _case(walk_rise=rise)
        for f in (0, 1):
            setting, coef = ss.drift_coef_on_cycles(ctx, e, fold == f)
            assert np.isinf(setting[0]) and setting[1] == -1.0
            rate = setting[1] * coef[-1]
            assert abs(rate - RATE) < 0.1 * abs(RATE), (rise, f, rate)
            assert coef[-2] == 0.0 and coef.size == 3
    # the level is the drift's at the clock's origin (t' = 0: the end of the calibration), measured on the cycles:
    # a walk whose misfit sits 1 um off does not move it
    for shift in (0.0, 1.0):
        ctx, e, fold = _case(walk_rise=0.0)
        e = e + shift * np.concatenate([np.full(int(np.sum(v)), float(i == 1)) for i, v in enumerate(ctx.valid)])
        _, coef = ss.drift_coef_on_cycles(ctx, e, fold >= 0)
        assert abs(coef[0] - (LEVEL - 70.0 * RATE)) < 0.02, (shift, coef[0])


def test_a_line_fitted_on_every_sample_is_pulled_by_the_walk():
    """Why the cycles: the same data's least-squares line beside one level is pulled to under half the rate."""
    ctx, e, _ = _case(walk_rise=0.17)
    t = np.concatenate([ss._session_time(ctx, s)[v] for s, v in zip(ctx.signals, ctx.valid)])
    slope = np.polyfit(t, e, 1)[0]
    assert abs(slope) < 0.5 * abs(RATE)


def test_no_repeated_drive_or_the_calibrations_session_give_no_size():
    ctx, e, fold = _case()
    ctx.signals[0].u = ctx.signals[1].u[:ctx.signals[0].u.size].copy()   # no repeated cycle any more
    assert ss.drift_coef_on_cycles(ctx, e, fold == 0) is None
    ctx, e, fold = _case()
    ctx.offset_of = lambda i: -1   # every recording in the calibration's session: no level of its own
    ctx.n_offset = lambda: 0
    assert ss.drift_coef_on_cycles(ctx, e, fold == 0) is None


def _cand(folds, dbic=16.0):
    return types.SimpleNamespace(name="thermal_drift", significant=False, veto=None, fold_ratios=list(folds),
                                 credited=1.0, dbic=dbic, p=4.6e-2, p_max=1.1e-3, discrimination=None,
                                 credited_only=False, setting=[(np.inf, 1.0)] * 2, coef=[np.zeros(3)] * 2)


HELD = {"recordings": [0], "cycles": [14], "slopes_um_per_s": [-0.00735], "changes_um": [-0.099],
        "second_half_um_per_s": [-0.007], "persists": True, "noise_um": [0.0056], "beyond_noise": True,
        "slope_um_per_s": -0.00735, "se_um_per_s": 0.0001, "t": -75.6, "dof": 12, "p": 1e-17}


def test_drift_on_cycles_sizes_a_candidate_whose_line_did_not_lower_the_error(monkeypatch):
    """s133-001's candidate: fold ratios 1.00/1.01, dBIC +16, its cycle means at t -75."""
    monkeypatch.setattr(ss, "cycle_mean_test", lambda *a: HELD)
    sized = ((np.inf, -1.0), np.array([0.0, 0.0, 0.0074]))
    monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a: sized)
    c = _cand([1.00, 1.01])
    ss.drift_on_cycles([c], [None, None], [None, None], np.zeros(1), lambda *a: None)
    assert c.significant and c.veto is None and c.from_cycles
    assert c.setting == [sized[0]] * 2 and c.coef[0] is sized[1] and "Sized there" in c.discrimination
    # no size on the cycles, or a rate against the cycle means' sign: not
    for out in (None, ((np.inf, 1.0), np.array([0.0, 0.0, 0.0074]))):
        monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a, _o=out: _o)
        c = _cand([1.00, 1.01])
        ss.drift_on_cycles([c], [None, None], [None, None], np.zeros(1), lambda *a: None)
        assert not c.significant and not getattr(c, "from_cycles", False)
    # the cycle means must hold: dying out, they do not
    monkeypatch.setattr(ss, "drift_coef_on_cycles", lambda *a: sized)
    monkeypatch.setattr(ss, "cycle_mean_test", lambda *a: {**HELD, "persists": False})
    c = _cand([1.00, 1.01])
    ss.drift_on_cycles([c], [None, None], [None, None], np.zeros(1), lambda *a: None)
    assert not c.significant
