"""Creep, thermal drift and a sensor offset told apart by their signatures (diagnose/slow_signature.py)."""

import types

import numpy as np
import pytest
from scipy.signal import fftconvolve

from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.select import Ctx, Signals, make_masks, slow_nuisance
from piezoctl.diagnose.slow_signature import ALPHA_SIGNATURE, SignatureTest, attribute, signature_tests
from piezoctl.models.hysteresis import hysteresis_parts

DT = 2e-3
NOISE_UM = 0.005


def _plane():
    return {"type": "plane", "r": [0.0, 0.2, 0.5], "knots": [[-1.5, 1.5]] * 3,
            "values": [[-3.0, 3.0], [-1.0, 1.0], [-2.0, 2.0]], "v_rest": 0.0, "offset": 0.0}


def _drives(rng):
    """Three reveal recordings of 12 s: steps with dwells, a triangle, steps again (normalized drive)."""
    steps = lambda n, dwell: np.repeat(rng.uniform(-0.9, 0.9, n), int(dwell / DT))
    t = np.arange(int(12 / DT)) * DT
    tri = 0.9 * (2 * np.abs(2 * ((t * 0.5) % 1) - 1) - 1)
    return [steps(6, 2.0), tri, steps(8, 1.5)]


def _ctx(rng, sessions_known=True):
    hp = _plane()
    base = {"hysteresis": hp, "dynamics": {"b": [1.0], "a": [1.0]}, "u_mid": 0.0, "u_half": 1.0, "terms": {}}
    sigs = []
    starts = [40.0, 60.0, 80.0]     # session clock of each recording's start [s], the calibration ended at 0
    for i, v in enumerate(_drives(rng)):
        t = np.arange(v.size) * DT
        h, hyst = hysteresis_parts(hp, v)
        sigs.append(Signals(name=f"rec{i}", t=t, u=v, y=h.copy(), u2=None, x2=None, temp=None, dt=DT, v=v, h=h,
                            hyst=hyst, yb=h.copy(), ydyn=h.copy(), index=i, t_session=starts[i]))
    valid, fold, block = make_masks(sigs, 0.5, 1.0)
    ctx = Ctx(base=base, signals=sigs, valid=valid, fold=fold, block=block, names=[s.name for s in sigs], n_rec=3,
              dt=DT, duration=12.0, u2_ref=0.0, y_center=0.0, y_half=6.0, u_lo=-0.9, u_hi=0.9, u_mid_all=0.0,
              u_half_all=0.9, max_step=1.8, peak_freqs=[], y_span=12.0, cal_u_lo=-1.0, cal_u_hi=1.0,
              drift_t0=0.0, drift_span=92.0)
    if sessions_known:
        ctx.offset_group, ctx.offset_sessions = [0, 0, 0], ["1"]
    return ctx


def _creep(s, g=0.03, t0=0.05, t1=10.0, pre_s=30.0):
    """A log-law creep of the hysteresis output (the foreign stage's law, written here from its docs): every
    change of h relaxes by g log10((1 + t/t0) / (1 + t/t1)) after it; the recording's first level was reached
    ``pre_s`` before it starts."""
    t = np.arange(s.h.size) * DT
    k = lambda x: g * np.log10((1 + x / t0) / (1 + x / t1))
    dh = np.diff(s.h, prepend=s.h[0])
    return fftconvolve(dh, k(t))[:s.h.size] + s.h[0] * k(t + pre_s)


def _drift(s, a=0.3, tau=60.0):
    ts = s.t_session + s.t
    return a * (1 - np.exp(-ts / tau)) + 0.05 * np.sin(2 * np.pi * ts / 70.0)


def _measured(ctx, effect, rng):
    """Measured output = the model's + ``effect(s)`` [um] + white noise; (residual, fold, block) of the used
    samples, recordings concatenated."""
    for s in ctx.signals:
        s.y = s.yb + effect(s) + NOISE_UM * rng.normal(size=s.t.size)
    e = np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])
    fold = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    return e, fold, block


def _run(ctx, effect, rng):
    e, fold, block = _measured(ctx, effect, rng)
    return {t.name: t for t in signature_tests([ctx, ctx], [e, e], [slow_nuisance(ctx)] * 2, fold, block, rows=200000)}


@pytest.mark.parametrize("effect,name", [(_creep, "creep"), (_drift, "thermal_drift"),
                                         (lambda s: np.full(s.t.size, 0.2), "sensor_offset")])
def test_each_slow_effect_is_held_by_its_own_signature(effect, name):
    rng = np.random.default_rng(3)
    ctx = _ctx(rng)
    tests = _run(ctx, effect, rng)
    assert tests[name].holds, tests
    assert tests[name].unique_ratio < 0.8
    others = [n for n in tests if n != name and not (name == "thermal_drift" and n == "sensor_offset")]
    for n in others:   # a drift also leaves a level (the offset's column): every other one must not hold
        assert not tests[n].holds, tests


def test_drift_goes_before_the_level_it_leaves_and_an_offset_alone_is_an_offset():
    rng = np.random.default_rng(4)
    ctx = _ctx(rng)
    tests = _run(ctx, _drift, rng)
    assert tests["sensor_offset"].holds and tests["thermal_drift"].holds
    evals = [_cand("sensor_offset", True, 0.4), _cand("thermal_drift", False, 0.6, p=2e-3), _cand("creep", False, 1.0)]
    text = attribute(evals, list(tests.values()))
    assert evals[0].name == "thermal_drift" and evals[0].significant and "thermal_drift" in text
    assert evals[1].name == "sensor_offset" and not evals[1].significant and evals[1].veto


def test_base_misfit_holds_no_signature():
    """A misfit the base's own refit can take (a wrong loop width) and an unknown initial state: none holds."""
    rng = np.random.default_rng(5)
    ctx = _ctx(rng)
    tests = _run(ctx, lambda s: 0.04 * s.hyst + 0.05 * np.exp(-s.t / 0.3) * (s.index == 1), rng)
    assert not any(t.holds for t in tests.values()), tests


def test_a_level_within_the_base_misfit_is_discounted():
    rng = np.random.default_rng(6)
    ctx = _ctx(rng)
    tests = _run(ctx, lambda s: np.full(s.t.size, 0.02), rng)
    t0 = tests["sensor_offset"]
    assert t0.holds and t0.credited == pytest.approx(t0.unique_ratio)   # no misfit estimate: nothing discounted
    ctx.misfit = {"slow_hz": 1.0, "mse_um2": {"level": 0.05 ** 2, "slow": 0.05 ** 2, "fast": 0.0}}
    t1 = _run(ctx, lambda s: np.full(s.t.size, 0.02), rng)["sensor_offset"]
    # a 20 nm level within a 50 nm misfit: what the band split assigns to the level and slow bands is not
    # credited (the rest, the cross terms between the bands, still is: misfit.credited_ratio)
    assert t1.credited > 0.9 > t0.credited


def _cand(name, significant, ratio, p=1e-6):
    return types.SimpleNamespace(name=name, significant=significant, veto=None, fold_ratios=[ratio, ratio],
                                 credited=ratio, dbic=-10.0, p=p, discrimination=None, slow_signature=None)


def _test(name, holds, ratio, p=None):
    p = (1e-6 if holds else 0.5) if p is None else p
    return SignatureTest(name=name, unique_ratio=ratio, fold_ratios=[ratio, ratio], credited=ratio, p=p,
                         n_active=20, holds=p < ALPHA_SIGNATURE, confirms=p < sg.ALPHA)


def test_a_passed_terms_own_signature_needs_only_the_family_level():
    """The passed term's own signature is one hypothesis (level ALPHA); switching the name to another is a search
    over three (ALPHA / 3)."""
    tests = [_test("creep", False, 0.63, p=5e-3), _test("thermal_drift", False, 1.1), _test("sensor_offset", False, 0.8)]
    evals = [_cand("creep", True, 0.33), _cand("sensor_offset", False, 0.7)]
    attribute(evals, tests)
    assert evals[0].name == "creep" and evals[0].significant and not evals[0].veto
    # the same p on a term that did not pass its own test does not take the name from the one that did
    tests = [_test("creep", False, 0.63, p=5e-3), _test("thermal_drift", False, 1.1), _test("sensor_offset", False, 0.8)]
    evals = [_cand("sensor_offset", True, 0.5), _cand("creep", False, 0.7)]
    attribute(evals, tests)
    assert not any(c.significant for c in evals) and evals[0].veto


def test_attribute_vetoes_a_slow_term_whose_signature_does_not_hold():
    evals = [_cand("creep", True, 0.4), _cand("sensor_offset", False, 0.9), _cand("thermal_drift", False, 0.95)]
    tests = [_test("creep", False, 0.99), _test("thermal_drift", False, 0.98), _test("sensor_offset", False, 0.97)]
    text = attribute(evals, tests)
    assert not evals[0].significant and "no slow signature holds" in evals[0].veto and "no slow" in text
    assert evals[0].slow_signature["holds"] is False


def test_attribute_names_the_holding_signature_only_when_its_candidate_has_the_size():
    # the offset passed its own test, creep's signature holds, but creep's candidate is too small: the offset's
    # own signature holds as well, so it keeps the name
    evals = [_cand("sensor_offset", True, 0.5), _cand("creep", False, 0.9)]
    tests = [_test("creep", True, 0.6), _test("sensor_offset", True, 0.7)]
    attribute(evals, tests)
    assert evals[0].name == "sensor_offset" and evals[0].significant
    # nothing slow passed: nothing changes
    evals = [_cand("sensor_offset", False, 0.5), _cand("creep", False, 0.5)]
    assert attribute(evals, tests) is None and not any(c.significant for c in evals)


def test_signature_level_is_bonferroni_over_three():
    assert ALPHA_SIGNATURE == pytest.approx(sg.ALPHA / 3)
