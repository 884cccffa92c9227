"""Cross-axis coupling's signature: its improvement follows the other axis' motion (diagnose/coupling_signature.py,
round 14)."""

import numpy as np

from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.coupling_signature import motion_columns, motion_test
from piezoctl.diagnose.select import Ctx, Signals, make_masks, slow_nuisance
from piezoctl.ident.terms import TERMS
from piezoctl.models.hysteresis import hysteresis_parts

DT = 2e-3
NOISE_UM = 0.005
U2_HOLD = 1.4   # [V] where the other axis is held (it was held there in the calibration too)


def _plane():
    return {"type": "plane", "r": [0.0, 0.2, 0.5], "knots": [[-1.5, 1.5]] * 3,
            "values": [[-3.0, 3.0], [-1.0, 1.0], [-2.0, 2.0]], "v_rest": 0.0, "offset": 0.0}


def _ctx(rng, u2s):
    """Three reveal recordings of 12 s (a triangle, a random walk of steps, a triangle), the other axis' drive
    ``u2s[i](t)`` [V] in each; one sensor session after the calibration's, on the session clock."""
    hp = _plane()
    base = {"hysteresis": hp, "dynamics": {"b": [1.0], "a": [1.0]}, "u_mid": 0.0, "u_half": 1.0, "terms": {}}
    t = np.arange(int(12 / DT)) * DT
    tri = lambda f: 0.8 * (2 * np.abs(2 * ((t * f) % 1) - 1) - 1)
    drives = [tri(0.5), np.repeat(rng.uniform(-0.8, 0.8, 12), t.size // 12), tri(0.3)]
    sigs = []
    for i, (v, starts) in enumerate(zip(drives, (40.0, 60.0, 80.0))):
        h, hyst = hysteresis_parts(hp, v)
        sigs.append(Signals(name=f"rec{i}", t=t, u=v, y=h.copy(), u2=u2s[i](t), x2=None, temp=None, dt=DT, v=v,
                            h=h, hyst=hyst, yb=h.copy(), ydyn=h.copy(), index=i, t_session=starts))
    valid, fold, block = make_masks(sigs, 0.5, 1.0)
    ctx = Ctx(base=base, signals=sigs, valid=valid, fold=fold, block=block, names=[s.name for s in sigs], n_rec=3,
              dt=DT, duration=12.0, u2_ref=U2_HOLD, y_center=0.0, y_half=6.0, u_lo=-0.8, u_hi=0.8, u_mid_all=0.0,
              u_half_all=0.8, max_step=1.6, peak_freqs=[], y_span=12.0, cal_u_lo=-1.0, cal_u_hi=1.0,
              drift_t0=0.0, drift_span=92.0)
    ctx.offset_group, ctx.offset_sessions = [0, 0, 0], ["1"]
    return ctx


def _held(t):
    return np.full(t.size, U2_HOLD)


def _sine(t):   # the null design's last recording: the other axis swept 35..115 V (s111-016)
    return 75.0 + 40.0 * np.sin(2 * np.pi * 1.3 * t)


def _run(ctx, effect, rng):
    for s in ctx.signals:
        s.y = s.yb + effect(s) + NOISE_UM * rng.normal(size=s.t.size)
    e = np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])
    fold = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    mt = motion_test([ctx, ctx], [e, e], [slow_nuisance(ctx)] * 2, [None, None], fold, block, rows=200000)
    return mt, e, fold


def _coupling_alone(ctx, e, fold):
    """Held-out RMS ratio of the coupling's own columns (level and motion together) with a constant for the
    session: what its own test sees."""
    X = np.vstack([TERMS["cross_coupling"].columns(ctx, s, None)[v] for s, v in zip(ctx.signals, ctx.valid)])
    X = np.column_stack([X, np.ones(X.shape[0])])
    out = []
    for f in (0, 1):
        tr, te = fold == f, fold == 1 - f
        th = np.linalg.lstsq(X[tr], e[tr], rcond=None)[0]
        out.append(np.sqrt(np.mean((e[te] - X[te] @ th) ** 2) / np.mean(e[te] ** 2)))
    return max(out)


def test_motion_part_is_zero_where_the_other_axis_is_held():
    rng = np.random.default_rng(1)
    ctx = _ctx(rng, [_held, _sine, _held])
    for s, v in zip(ctx.signals, ctx.valid):
        m, lv = motion_columns(ctx, s, v, None)
        X = TERMS["cross_coupling"].columns(ctx, s, None)
        assert np.allclose(m + lv, X)
        if s.index != 1:
            assert np.all(m == 0.0)
        else:
            assert np.sqrt(np.mean(m[:, 0] ** 2)) > 20.0   # the sweep's motion [V]


def test_true_coupling_follows_the_motion():
    """The other axis moves in two recordings (sines, a triangle) and 3 % of it (through this axis' dynamics,
    here unity) shows in the output: the motion test holds."""
    rng = np.random.default_rng(2)
    tri2 = lambda t: 75.0 + 70.0 * (2 * np.abs(2 * ((t * 1.1) % 1) - 1) - 1)
    ctx = _ctx(rng, [_sine, tri2, _held])
    mt, _, _ = _run(ctx, lambda s: 0.03 * (s.u2 - U2_HOLD), rng)
    assert mt["holds"], mt
    assert mt["ratio"] < 0.2 and mt["p"] < sg.ALPHA


def test_drift_taken_by_the_level_of_u2_does_not_hold():
    """s111-016's pattern: a drift on the session clock, the other axis held everywhere but one recording where
    it is swept about another mean. The coupling's own columns take the drift (its level and slope in that
    recording); its motion beyond them does not."""
    rng = np.random.default_rng(3)
    ctx = _ctx(rng, [_held, _held, _sine])
    drift = lambda s: -0.3 * (1 - np.exp(-(s.t_session + s.t) / 40.0))
    mt, e, fold = _run(ctx, drift, rng)
    assert _coupling_alone(ctx, e, fold) < 0.8   # what the coupling's own test saw: it takes the drift
    assert not mt["holds"], mt


def test_null_with_the_other_axis_moving_does_not_hold():
    rng = np.random.default_rng(4)
    ctx = _ctx(rng, [_held, _sine, _held])
    mt, _, _ = _run(ctx, lambda s: np.zeros(s.t.size), rng)
    assert not mt["holds"], mt


def test_selection_vetoes_a_coupling_candidate_whose_motion_does_not_hold():
    """select._coupling_motion: the drift case's significant coupling candidate is vetoed with the figures; the
    true coupling's is kept, its figures in ``signature_check``."""
    from piezoctl.diagnose.select import Candidate, _coupling_motion

    def cand():
        return Candidate(term=TERMS["cross_coupling"], ratio=0.4, fold_ratios=[0.4, 0.4], nrmse_before=0.01,
                         nrmse_after=0.004, t=5.0, p=1e-6, n_active=20, p_max=1e-3, dbic=-50.0, n_eff=100.0,
                         significant=True, setting=[None, None], coef=[None, None])

    for u2s, effect, kept in (([_held, _held, _sine], lambda s: -0.3 * (1 - np.exp(-(s.t_session + s.t) / 40.0)),
                               False),
                              ([_sine, _sine, _held], lambda s: 0.03 * (s.u2 - U2_HOLD), True)):
        rng = np.random.default_rng(5)
        ctx = _ctx(rng, u2s)
        _, e, fold = _run(ctx, effect, rng)
        block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
        c = cand()
        _coupling_motion([c], [ctx, ctx], [e, e], fold, block, 200000, lambda *a: None)
        assert c.significant is kept and (c.veto is None) is kept, c.veto
        assert c.signature_check["passed"] is kept and "motion" in c.signature_check


def test_after_a_first_term_a_small_coupling_is_named_by_its_motion_and_a_null_is_not():
    """Round 18: after a first term a coupling is tested at the further gate (select.CHECKED_TERMS) and kept only when
    its motion holds. A coupling (the other axis' motion about its mean) worth a held-out ratio of about 0.9 beside
    60 nm left by the first term fails the first round's 0.8 gate, passes the further one, and its motion test keeps
    it; with the same leftover and the other axis swept in one recording but no coupling, nothing is kept.
    (A drift taken by the coupling's level columns: test_selection_vetoes_a_coupling_candidate_whose_motion_does_not_hold.)"""
    from piezoctl.diagnose import select as S

    left = lambda s: 0.06 * np.random.default_rng(100 + s.index).normal(size=s.t.size)
    term = TERMS["cross_coupling"]
    p_max = sg.ALPHA / 10
    for u2s, effect, kept in (([_sine, _sine, _held], lambda s: 0.0012 * (s.u2 - s.u2.mean()) + left(s), True),
                              ([_held, _sine, _held], left, False)):
        rng = np.random.default_rng(6)
        ctx = _ctx(rng, u2s)
        _, e, fold = _run(ctx, effect, rng)
        block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
        later = S._evaluate([ctx, ctx], term, [e, e], fold, block, 200000, p_max, S._ratio_max(term, ["a term"]))
        if kept:
            first = S._evaluate([ctx, ctx], term, [e, e], fold, block, 200000, p_max, S._ratio_max(term, []))
            assert not first.significant and max(first.fold_ratios) > sg.RATIO_MAX, first.fold_ratios
            assert later.significant and later.below_gates, (later.fold_ratios, later.credited, later.p)
        S._coupling_motion([later], [ctx, ctx], [e, e], fold, block, 200000, lambda *a: None)
        assert (later.significant and later.veto is None) is kept, (later.fold_ratios, later.p, later.veto)


def test_later_round_coupling_not_significant_on_the_whole_residual_is_judged_on_its_motion():
    """Round 25, select._coupling_motion with ``later``: after a first term, a coupling candidate that lowered each
    fold (credited below 1) but failed the whole residual's block test is made significant when its motion test
    holds at the round's level ``p_max``; with no coupling (the other axis swept in one recording) it stays not
    significant; in the first round, or when a fold got worse, the motion test is not asked."""
    from piezoctl.diagnose.select import Candidate, _coupling_motion

    def cand(fold_ratios=(0.98, 0.97)):
        return Candidate(term=TERMS["cross_coupling"], ratio=0.975, fold_ratios=list(fold_ratios),
                         nrmse_before=0.01, nrmse_after=0.00975, t=1.5, p=6e-2, n_active=13, p_max=1e-3, dbic=11.0,
                         n_eff=100.0, significant=False, setting=[None, None], coef=[None, None], credited=0.99,
                         ratio_max=1.0, selection_round=2)

    cases = (([_sine, _sine, _held], lambda s: 0.03 * (s.u2 - U2_HOLD), True),
             ([_held, _sine, _held], lambda s: np.zeros(s.t.size), False))
    for u2s, effect, coupled in cases:
        rng = np.random.default_rng(7)
        ctx = _ctx(rng, u2s)
        _, e, fold = _run(ctx, effect, rng)
        block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
        logged = []
        c = cand()
        _coupling_motion([c], [ctx, ctx], [e, e], fold, block, 200000, logged.append, later=True)
        assert c.significant is coupled and c.veto is None, (c.significant, logged)
        assert any("on its motion" in x for x in logged), logged
        if coupled:
            assert c.signature_check["passed"] and c.signature_check["motion"]["p"] < c.p_max
            assert "not significant" in c.discrimination
        else:
            assert c.signature_check is None
        first = cand()   # the first round: no motion test, nothing changes
        _coupling_motion([first], [ctx, ctx], [e, e], fold, block, 200000, logged.append, later=False)
        worse = cand((0.98, 1.01))   # a fold got worse: not offered to the motion test
        _coupling_motion([worse], [ctx, ctx], [e, e], fold, block, 200000, logged.append, later=True)
        for x in (first, worse):
            assert not x.significant and x.signature_check is None and x.veto is None
