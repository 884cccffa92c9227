"""Round 15: the rate term is a rate-dependent loop *width* (the base plane's plays with thresholds that grow with
the rate they move at), not a rate-dependent gain on the hysteretic part (docs/diagnose-rounds/round-15.md, "Round 15: rate
dependence")."""

import numpy as np
import pytest

from piezoctl.diagnose import select as S
from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.run import locate
from piezoctl.dsp import drive_rate, filt
from piezoctl.ident import refined
from piezoctl.ident.terms import TERMS
from piezoctl.io.recording import Recording
from piezoctl.models.hysteresis import plane_width_change, plays_varying
from piezoctl.models.play import play_outputs
from play_reference import per_sample_plays

FS = 10_000.0


@pytest.mark.parametrize("seed", range(4))
def test_varying_plays_are_the_classical_plays_at_constant_thresholds(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 3000))
    v = np.cumsum(rng.normal(size=n)) / 20
    if seed % 2:
        v = np.round(v, 1)        # holds
    r = rng.uniform(0, 0.5, 5)
    y0 = rng.normal(size=5) * 0.2
    assert np.array_equal(plays_varying(v, np.tile(r, (n, 1)), y0), play_outputs(v, r, y0=y0))


def test_varying_plays_follow_the_recursion_while_thresholds_grow():
    """Thresholds that never shrink: the runs' form is the per-sample recursion exactly."""
    rng = np.random.default_rng(7)
    n = 4000
    v = np.sin(np.linspace(0, 40, n)) * np.linspace(0.3, 1.0, n) + rng.normal(0, 0.01, n)
    R = np.outer(1 + np.linspace(0, 1.5, n) ** 2, [0.05, 0.2, 0.4])
    y0 = np.zeros(3)
    assert np.allclose(plays_varying(v, R, y0), per_sample_plays(v, R, y0), rtol=0, atol=1e-12)


def _plane(rng):
    r = [0.0, 0.1, 0.25, 0.45]
    knots = [np.linspace(-1.2 + x, 1.2 - x, 9) for x in r]
    values = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 1.0, k.size - 1))]) - 2.0 for k in knots]
    return {"type": "plane", "r": r, "knots": [k.tolist() for k in knots], "values": [x.tolist() for x in values],
            "offset": 0.0, "v_rest": 0.0, "v_lo": -1.0, "v_hi": 1.0}


def test_the_width_stays_in_the_memory_after_a_fast_stroke():
    """A fast stroke up then a slow return: on the slow part the rate factor is 1, yet the plays that last moved
    fast keep their wider threshold until the drive pushes them again, so the output still differs; a gain on the
    hysteretic part at the rate of the moment (the law before round 15) is zero there."""
    hp = _plane(np.random.default_rng(1))
    dt = 1 / FS
    up = np.linspace(-0.9, 0.9, 200)             # 0.02 s: 90 FS/s
    down = np.linspace(0.9, 0.6, 20000)[1:]      # 2 s: 0.15 FS/s
    v = np.concatenate([np.full(2000, -0.9), up, down])
    term = TERMS["rate_dependent_hysteresis"]
    d = term.widened(hp, v, dt, 10.0, 1.0)    # the stroke at 9x ref, the return at 1/60 of it
    slow = slice(2200 + 5000, 2200 + 9000)       # well after the turn, still inside the widest play's hold
    assert term.width(v, dt, 10.0, 1.0)[slow].max() < 1.02
    assert np.min(np.abs(d[slow])) > 0.05 * np.max(np.abs(d))
    from piezoctl.models.hysteresis import hysteresis_parts
    old = term.basis(v, hysteresis_parts(hp, v)[1], dt, 10.0)
    assert np.max(np.abs(old[slow])) < 0.2 * np.min(np.abs(d[slow]))


def _stage(rng):
    """A stage whose plays widen with the rate (the term's own law at ref 10 FS/s, k 0.8), recorded with sines of
    three rates and a slow triangle; the base is its rate-independent plane."""
    base = {"fs_hz": FS, "u_mid": 75.0, "u_half": 75.0, "hysteresis": _plane(rng),
            "dynamics": {"b": [0.3, 0.2], "a": [1.0, -0.5]}, "terms": {}}
    t = np.arange(int(4 * FS)) / FS
    drives = [75 + 55 * np.sin(2 * np.pi * f * t) for f in (1.0, 6.0, 25.0)]
    drives.append(75 + 60 * (2 * np.abs(((t * 0.5) % 1) - 0.5) * 2 - 1))
    return base, t, drives


@pytest.mark.parametrize("law", ["width", "none", "too_wide"])
def test_a_widening_loop_is_found_and_a_rate_independent_stage_is_not(law):
    """The term's own law is found at its reference; nothing on a rate-independent stage; and a fit that asks the
    loop to widen far beyond what rate dependence does (gain 6 at k 0.8: 5.8-fold) is vetoed with the reason."""
    rng = np.random.default_rng(3)
    base, t, drives = _stage(rng)
    true = {"gain": 6.0 if law == "too_wide" else 1.0, "ref_fs_per_s": 10.0, "width_k": 0.8, "rate_cutoff_hz": 50.0}
    stage = dict(base, terms={"rate_dependent_hysteresis": true} if law != "none" else {})
    recs = [Recording(t=t, u=u, y=refined.simulate(stage, t, u) + rng.normal(0, 0.005, t.size), path=f"r{i}.csv")
            for i, u in enumerate(drives)]
    ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = S.residual(ctx)
    c = S._evaluate([ctx, ctx], TERMS["rate_dependent_hysteresis"], [e, e], fold_all, block_all, 10 ** 6,
                    sg.ALPHA / 12)
    if law == "width":
        assert c.significant and max(c.fold_ratios) < 0.2
        assert all(abs(np.log(st[0] / 10.0)) < np.log(3.0) for st in c.setting)
    elif law == "too_wide":
        assert max(c.fold_ratios) < 0.2 and c.p < sg.ALPHA / 12    # it fits, and is refused for its size
        assert not c.significant and "wide" in c.veto
    else:
        assert not c.significant


def _constant_wider(hp, f):
    """``hp`` with every play's threshold (and its knots, which span the play's range) x ``f``."""
    out = dict(hp)
    out["r"] = [float(r) * f for r in hp["r"]]
    return out


def test_a_constant_widening_is_not_credited_to_the_rate():
    """Round 16: a stage whose plays are all 30 % wider than the base's, at every rate, is the base's own error.
    Recorded with triangles (the rate constant along each stroke, far above a low reference), round 15's width law
    took it (fold ratios 0.57/0.49, p 4e-15: at a low reference the rate factor is near 1 on every stroke, a
    constant widening); nested against the constant widening x (1 + k) it must not pass, while the rate's own law
    added to the same stage is still found beyond it."""
    rng = np.random.default_rng(4)
    base, t, _ = _stage(rng)
    drives = [75 + a * (2 * np.abs(((t * f) % 1) - 0.5) * 2 - 1) for f, a in ((1.0, 55), (3.0, 50), (0.5, 60),
                                                                               (0.5, 60))]
    term = TERMS["rate_dependent_hysteresis"]
    for law in ("constant", "constant+rate"):
        stage = dict(base, hysteresis=_constant_wider(base["hysteresis"], 1.3))
        if law == "constant+rate":
            stage["terms"] = {"rate_dependent_hysteresis": {"gain": 1.0, "ref_fs_per_s": 10.0, "width_k": 0.8,
                                                            "rate_cutoff_hz": 50.0}}
        recs = [Recording(t=t, u=u, y=refined.simulate(stage, t, u) + rng.normal(0, 0.005, t.size),
                          path=f"r{i}.csv") for i, u in enumerate(drives)]
        ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
        fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
        block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
        e = S.residual(ctx)
        assert np.sqrt(np.mean(e ** 2)) > 0.3          # the widening is far above the noise (0.005 um)
        c = S._evaluate([ctx, ctx], term, [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12)
        if law == "constant":
            assert not c.significant and min(c.fold_ratios) > 0.9
        else:
            assert c.significant and max(c.fold_ratios) < 0.5


def test_a_loop_carried_by_the_bouc_wen_column_widens_too():
    """Round 16: a plane whose loop lies mostly in its Bouc-Wen column (one narrow play, as the generalized-PI bases
    of s112-035 and s112-051) on a stage where the whole loop widens with the rate - the play's threshold and the
    column's size both x (1 + 0.8 r / (r + 10 FS/s)). Widening the plays alone (round 15) leaves most of it; the
    term that scales the column by the same factor finds it, at its reference."""
    from piezoctl.models.hysteresis import bouc_wen_h
    rng = np.random.default_rng(5)
    base, t, drives = _stage(rng)
    hp = {"type": "plane", "r": [0.0, 0.08], "knots": [[-1.2, 1.2], [-1.1, 1.1]], "values": [[-6.0, 6.0], [-0.4, 0.4]],
          "offset": 0.0, "v_rest": 0.0, "v_lo": -1.0, "v_hi": 1.0, "bw": {"beta": 2.0, "gamma": 0.4, "c_h": 2.5}}
    base = dict(base, hysteresis=hp)
    term = TERMS["rate_dependent_hysteresis"]
    dyn = base["dynamics"]
    recs = []
    for i, u in enumerate(drives):   # the truth written out from the operator's parts, not through the term
        v = (u - 75.0) / 75.0
        w = 1.0 + 0.8 * (term.width(v, 1 / FS, 10.0, 1.0) - 1.0)   # 1 + 0.8 c
        extra = plane_width_change(hp, v, w) + (w - 1.0) * 2.5 * bouc_wen_h(v, 2.0, 0.4)
        y = refined.simulate(base, t, u) + filt(dyn["b"], dyn["a"], extra) + rng.normal(0, 0.005, t.size)
        recs.append(Recording(t=t, u=u, y=y, path=f"r{i}.csv"))
    ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = S.residual(ctx)
    c = S._evaluate([ctx, ctx], term, [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12)
    assert c.significant and max(c.fold_ratios) < 0.2
    assert all(abs(np.log(st[0] / 10.0)) < np.log(3.0) for st in c.setting)


def test_round_15_files_widen_the_plays_only():
    """A model file with ``width_k`` but no ``widen_bw`` (round 15) simulates the plays widened and the Bouc-Wen
    column as it was; with ``widen_bw`` the column is scaled by the width factor less one."""
    from piezoctl.models.hysteresis import bouc_wen_h
    rng = np.random.default_rng(6)
    base, t, drives = _stage(rng)
    hp = dict(base["hysteresis"], bw={"beta": 2.0, "gamma": 0.4, "c_h": 2.5})
    base = dict(base, hysteresis=hp)
    u = drives[2]
    v = (u - 75.0) / 75.0
    y0 = refined.simulate(base, t, u)
    old = {"gain": 0.7, "ref_fs_per_s": 5.0, "width_k": 1.0, "rate_cutoff_hz": 50.0}
    w = TERMS["rate_dependent_hysteresis"].width(v, 1 / FS, 5.0, 1.0)
    d_old = refined.simulate(dict(base, terms={"rate_dependent_hysteresis": old}), t, u) - y0
    d_new = refined.simulate(dict(base, terms={"rate_dependent_hysteresis": dict(old, widen_bw=True)}), t, u) - y0
    dyn = base["dynamics"]
    assert np.allclose(d_old, filt(dyn["b"], dyn["a"], 0.7 * plane_width_change(hp, v, w)), rtol=0, atol=1e-9)
    want_bw = filt(dyn["b"], dyn["a"], 0.7 * (w - 1.0) * 2.5 * bouc_wen_h(v, 2.0, 0.4))
    assert np.allclose(d_new - d_old, want_bw, rtol=0, atol=1e-9) and np.max(np.abs(want_bw)) > 0.1


def test_the_widening_bound():
    """The widening is taken at the recordings' fastest settled rate: a large gain at a reference far above every
    rate the drive reaches is a small widening."""
    from types import SimpleNamespace
    t = np.arange(int(FS)) / FS
    v = 0.8 * np.sin(2 * np.pi * 10 * t)               # up to 50 FS/s
    ctx = SimpleNamespace(signals=[SimpleNamespace(v=v, dt=1 / FS)], valid=[t > 0.1],
                          base={"hysteresis": _plane(np.random.default_rng(0))})
    term = TERMS["rate_dependent_hysteresis"]
    lead = [5.0] * term.n_nuisance(ctx)    # the constant widening's and shift's gains (rounds 16, 24) do not count
    assert len(lead) == len(term.CONSTANT_K) + len(term.CONSTANT_D)
    assert term.implausible(ctx, (3.0, 1.0), lead + [1.8, 0.1]) is None
    assert term.implausible(ctx, (3000.0, 1.0), lead + [100.0, 0.1]) is None    # 100 x 50 / 3050 = 1.6
    assert "wide" in term.implausible(ctx, (30.0, 1.0), lead + [273.0, 0.0])     # two-effect s113-001's gain
    assert "wide" in term.implausible(ctx, (3.0, 1.0), lead + [3.5, 0.0])
    # round 23: the delay s129-007's all-data fit, 10.7 x 0.5 x c at a reference just above the fastest rate
    # (c 0.55: 2.9), is a lag's ellipse, not a wider loop; the largest widening of a rate case named in seeds
    # 115-130 (1.29) is not
    r = 50.0 * 16466.0 / 19775.0      # its reference, scaled to this drive's fastest rate
    assert "wide" in term.implausible(ctx, (r, 0.5), lead + [10.66, 0.0])
    assert term.implausible(ctx, (r, 1.0), lead + [1.29 / (50.0 / (50.0 + r)), 0.0]) is None


def test_old_model_files_keep_the_gain_law():
    """A model file without ``width_k`` (rounds up to 14) simulates the hysteretic part scaled by the rate."""
    rng = np.random.default_rng(2)
    base, t, drives = _stage(rng)
    u = drives[2]
    y0 = refined.simulate(base, t, u)
    old = {"gain": 0.3, "ref_fs_per_s": 5.0, "rate_cutoff_hz": 50.0}
    y1 = refined.simulate(dict(base, terms={"rate_dependent_hysteresis": old}), t, u)
    p = refined.simulate_parts(base, t, u)
    want = filt(base["dynamics"]["b"], base["dynamics"]["a"],
                0.3 * TERMS["rate_dependent_hysteresis"].basis(p["v"], p["hyst"], 1 / FS, 5.0))
    assert np.allclose(y1 - y0, want, rtol=0, atol=1e-9)
    assert np.max(np.abs(want)) > 0.01


def test_a_base_without_plays_keeps_the_gain_law():
    """A plane of the reversible curve and a Bouc-Wen column (the own-stage cases' bases) has no thresholds to
    widen: the term's settings are the references alone and its columns the old law's, through G."""
    from types import SimpleNamespace
    hp = {"type": "plane", "r": [0.0], "knots": [[-1.0, 1.0]], "values": [[-5.0, 5.0]], "offset": 0.0,
          "v_rest": 0.0, "v_lo": -1.0, "v_hi": 1.0, "bw": {"beta": 2.0, "gamma": 0.4, "c_h": 1.5}}
    base = {"fs_hz": FS, "u_mid": 75.0, "u_half": 75.0, "hysteresis": hp,
            "dynamics": {"b": [0.3, 0.2], "a": [1.0, -0.5]}, "terms": {}}
    t = np.arange(int(FS)) / FS
    u = 75 + 60 * np.sin(2 * np.pi * 20 * t)
    p = refined.simulate_parts(base, t, u)
    term = TERMS["rate_dependent_hysteresis"]
    ctx = SimpleNamespace(base=base)
    s = SimpleNamespace(v=p["v"], hyst=p["hyst"], dt=1 / FS)
    assert term.settings(ctx) == list(term.REFS)
    want = filt([0.3, 0.2], [1.0, -0.5], term.basis(p["v"], p["hyst"], 1 / FS, 3.0))
    assert np.allclose(term.columns(ctx, s, 3.0), want) and np.max(np.abs(want)) > 0.1
    assert "width_k" not in term.model_params(ctx, 3.0, [0.3])


def test_a_loop_of_its_own_size_in_each_recording_is_not_credited_to_the_rate():
    """Round 17: the term nested per recording against the hysteresis groups (``test_nuisance``). A rate-independent
    stage whose loop (the plays' part) is 0.85, 1 and 1.2 times the base's in three recordings, each a triangle at
    its own rate, is not credited (on this synthetic stage round 16's nesting does not take it either, 0.96/1.04:
    the evidence that it matters is null s115-009, docs/diagnose-rounds/round-17.md "Round 17"); the rate's own law is still found
    beyond a loop size of its own in each recording when one recording holds sines at three rates, as the foreign
    reveal does."""
    from piezoctl.models.hysteresis import scale_groups
    rng = np.random.default_rng(7)
    base, t, _ = _stage(rng)
    tri = [75 + a * (2 * np.abs(((t * f) % 1) - 0.5) * 2 - 1) for f, a in ((1.0, 55), (3.0, 55), (0.5, 55))]
    gains = [-0.15, 0.0, 0.2]
    term = TERMS["rate_dependent_hysteresis"]

    def evaluate(drives, stages):
        recs = [Recording(t=t, u=u, y=refined.simulate(st, t, u) + rng.normal(0, 0.005, t.size), path=f"r{i}.csv")
                for i, (u, st) in enumerate(zip(drives, stages))]
        ctx, _, _ = locate(base, [recs[-1]], recs, [r.path for r in recs], 0.5, 0.5)
        fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
        block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
        e = S.residual(ctx)
        return ctx, S._evaluate([ctx, ctx], term, [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12), e

    sized = [dict(base, hysteresis=scale_groups(base["hysteresis"], [0.0, g])) for g in gains]
    ctx, c, e = evaluate(tri, sized)
    assert np.sqrt(np.mean(e ** 2)) > 0.1                  # far above the noise (0.005 um)
    assert not c.significant and min(c.fold_ratios) > 0.8
    assert ctx.refit_cache[("rate: widening per recording",)][2].shape[1] == 2 * 2   # two recordings' groups
    law = {"gain": 1.0, "ref_fs_per_s": 10.0, "width_k": 0.8, "rate_cutoff_hz": 50.0}
    f = np.array([1.0, 6.0, 25.0])[np.minimum(3 * np.arange(t.size) // t.size, 2)]   # Hz, a third each
    drives = [75 + 55 * np.sin(2 * np.pi * np.cumsum(f) / FS), tri[2]]
    _, c, _ = evaluate(drives, [dict(base, terms={"rate_dependent_hysteresis": law})] * 2)
    assert c.significant and max(c.fold_ratios) < 0.5


def test_a_narrowing_is_zero_at_the_calibrations_rates_and_moves_every_threshold_alike():
    """Round 24: the narrowing's threshold shift is zero wherever the drive is no faster than the calibration's
    fastest rate (the base holds the loop there), and beyond it every play's threshold moves in by the same amount
    whatever its size, clipped at 0."""
    hp = _plane(np.random.default_rng(8))
    dt = 1 / FS
    term = TERMS["rate_dependent_hysteresis"]
    t = np.arange(int(2 * FS)) / FS
    slow = 0.8 * np.sin(2 * np.pi * 0.5 * t)              # up to 2.5 FS/s
    floor = float(np.max(drive_rate(slow, dt)))
    assert np.all(term.narrowing_shift(slow, dt, 10.0, 0.05, floor) == 0.0)
    assert np.all(term.narrowed(hp, slow, dt, 10.0, 0.05, floor) == 0.0)
    fast = 0.8 * np.sin(2 * np.pi * 20 * t)               # up to 100 FS/s
    sh = term.narrowing_shift(fast, dt, 10.0, 0.05, floor)
    assert 0.03 < sh.max() < 0.05
    want = plane_width_change(hp, fast, np.ones(t.size), np.full(t.size, 0.12))
    r = np.asarray(hp["r"])
    smaller = dict(hp, r=[float(x) for x in np.where(r > 0, np.maximum(r - 0.12, 0.0), 0.0)])
    from piezoctl.models.hysteresis import hysteresis_output
    got = hysteresis_output(smaller, fast) - hysteresis_output(hp, fast)
    assert np.max(np.abs(want)) > 0.05 and np.allclose(want, got, rtol=0, atol=1e-9)


def _evaluate_on_shifted_stage(term, shift):
    """(ctx, residual [um], the term's candidate) on ``_stage``'s rate-independent plane (seed 9) whose plays'
    thresholds all move in by ``shift(v)`` [half-span of the drive] per sample, written out here (not through the
    term), recorded with the sines at three rates and the slow triangle as calibration; noise 5 nm."""
    rng = np.random.default_rng(9)
    base, t, drives = _stage(rng)
    hp, dyn = base["hysteresis"], base["dynamics"]
    recs = []
    for i, u in enumerate(drives):
        v = (u - 75.0) / 75.0
        extra = plane_width_change(hp, v, np.ones(v.size), shift(v))
        y = refined.simulate(base, t, u) + filt(dyn["b"], dyn["a"], extra) + rng.normal(0, 0.005, t.size)
        recs.append(Recording(t=t, u=u, y=y, path=f"r{i}.csv"))
    ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = S.residual(ctx)
    return ctx, e, S._evaluate([ctx, ctx], term, [e, e], fold_all, block_all, 10 ** 6, sg.ALPHA / 12)


@pytest.mark.parametrize("law", ["narrow", "none"])
def test_a_narrowing_loop_is_found_and_a_rate_independent_stage_is_not(law):
    """Round 24: a stage whose plays' thresholds move in with the rate, the same amount for each (0.1 x r / (r +
    10 FS/s) from rest, written out here, not through the term), recorded with sines at three rates (the slow
    triangle is its calibration) is found by the narrowing settings; the widening settings alone leave it (the
    widening's gain sits at its bound 0); a rate-independent stage is not credited."""
    def shift(v):
        r = drive_rate(v, 1 / FS)
        return 0.1 * r / (r + 10.0) if law == "narrow" else np.zeros(v.size)
    term = TERMS["rate_dependent_hysteresis"]
    ctx, e, c = _evaluate_on_shifted_stage(term, shift)
    if law == "narrow":
        assert np.sqrt(np.mean(e ** 2)) > 0.05               # far above the noise (0.005 um)
        assert c.significant and max(c.fold_ratios) < 0.5
        assert all(st[1] < 0 for st in c.setting)
        doc = term.model_params(ctx, c.setting[0], c.coef[0])
        assert doc["width_k"] < 0 and doc["rate_floor_fs_per_s"] > 0
    else:
        assert not c.significant


def test_each_family_is_nested_against_its_own_counterpart():
    """Round 25: the constant shift is the narrowing's rate-independent counterpart only. A widening setting's
    shift columns are zero and its model has no shift; a narrowing setting's are the plane with every threshold
    less 0.05 and 0.1 and its model keeps their gains."""
    rng = np.random.default_rng(5)
    base, t, drives = _stage(rng)
    term = TERMS["rate_dependent_hysteresis"]
    recs = [Recording(t=t, u=u, y=refined.simulate(base, t, u) + rng.normal(0, 0.005, t.size), path=f"r{i}.csv")
            for i, u in enumerate(drives)]
    ctx, _, _ = locate(base, recs[3:], recs, [r.path for r in recs], 0.5, 0.5)
    s = ctx.signals[0]
    nk, n = len(term.CONSTANT_K), term.n_nuisance(ctx)
    wide, narrow = term.columns(ctx, s, (10.0, 0.5)), term.columns(ctx, s, (10.0, -0.05))
    assert np.all(wide[:, nk:n] == 0.0) and np.all(np.any(narrow[:, nk:n] != 0.0, axis=0))
    assert np.array_equal(wide[:, :nk], narrow[:, :nk])
    assert term.family((10.0, 0.5)) != term.family((10.0, -0.05))
    coef = np.arange(1.0, n + 2.0)
    assert "constant_shift" not in term.model_params(ctx, (10.0, 0.5), coef)
    assert term.model_params(ctx, (10.0, -0.05), coef)["constant_shift_gain"] == list(coef[nk:n])


def test_a_loop_narrower_at_every_rate_is_not_credited_to_the_rate():
    """Round 25: a stage whose plays' thresholds are all 0.05 of the half-span narrower than the base's at every
    rate (the shape in which a KP stage's base misfits its loop on every recording, round 24) is the base's own
    error: the narrowing settings are credited only beyond their own constant shift, so with the "before" of
    another family (the widening's, without the shift) this would pass."""
    term = TERMS["rate_dependent_hysteresis"]
    _, e, c = _evaluate_on_shifted_stage(term, lambda v: np.full(v.size, 0.05))
    assert np.sqrt(np.mean(e ** 2)) > 0.05               # far above the noise (0.005 um)
    assert not c.significant and min(c.fold_ratios) > 0.9


def _narrowing_ctx(amplitude):
    """A reveal of fast sines of ``amplitude`` [FS] (60 Hz) around mid-range beside a slow calibration triangle
    (0.5 Hz over the full span), on ``_plane``'s stage (widest play 0.45)."""
    from types import SimpleNamespace
    t = np.arange(int(FS)) / FS
    v = amplitude * np.sin(2 * np.pi * 60 * t)
    cal = np.interp(t, [0, 0.5, 1.0], [-0.9, 0.9, -0.9])
    base = {"hysteresis": _plane(np.random.default_rng(0)), "u_mid": 0.0, "u_half": 1.0}
    return SimpleNamespace(signals=[SimpleNamespace(v=v, dt=1 / FS)], valid=[t > 0.1], base=base,
                           cal=[SimpleNamespace(u=cal, dt=1 / FS)], cal_k0=[0], refit_cache={})


def test_a_narrowing_that_closes_the_strokes_it_acts_on_is_refused():
    """Round 28: a threshold shift of 0.3 of the half-span (below the widest play, 0.45: round 24's bound does
    not act) on sines of half excursion 0.05 would close every play they reverse - what it changes is the state of
    plays the sines never reverse, a level (the held-out null s139-009) - refused; the same shift on sines of 0.8,
    and the rate cases' 0.03 on either, are a narrower loop."""
    term = TERMS["rate_dependent_hysteresis"]
    small, large = _narrowing_ctx(0.05), _narrowing_ctx(0.8)
    lead = [0.0] * term.n_nuisance(small)
    ref = 1.0                                          # FS/s, far below the sines' rates: c near 1
    assert "close every play" in term.implausible(small, (ref, -0.1), lead + [3.0, 0.0])
    assert term.implausible(large, (ref, -0.1), lead + [3.0, 0.0]) is None
    assert term.implausible(small, (ref, -0.1), lead + [0.3, 0.0]) is None
    assert term.implausible(large, (ref, -0.1), lead + [0.3, 0.0]) is None
    # the shift is measured beyond the calibration's fastest rate: a sine no faster than the calibration is not
    # narrowed at all, whatever the gain below the widest play
    slow = _narrowing_ctx(0.05)
    slow.signals[0].v = 0.05 * np.sin(2 * np.pi * 0.5 * np.arange(int(FS)) / FS)
    assert term.implausible(slow, (ref, -0.1), lead + [3.0, 0.0]) is None
