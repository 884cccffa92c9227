"""Round 11: what the data cannot separate (docs/diagnose-rounds/round-11.md, "Round 11: what the data cannot separate").

Synthetic residuals with known structure: two collinear regressors are reported as a pair, an orthogonal one is
not; an offset no larger than the base's own level misfit is refused, a large one kept; a slew candidate whose
improvement also lies below its limit fails its check; the bench counts a truth inside the pair on its own line.
"""

import dataclasses
import types

import numpy as np
import pytest

from piezoctl.bench.foreign_diagnose import ambiguous
from piezoctl.diagnose.discriminate import (beyond_test, inseparable_lines, pair_verdict, separate,
                                            separation_doc)
from piezoctl.diagnose.signature import check_slew_absent
from piezoctl.diagnose.slow_signature import offset_level_test

DT = 1e-3
N_BLOCKS = 40
BLOCK = 500


def layout(n_rec=1):
    """fold, block and recording of ``n_rec`` recordings of N_BLOCKS blocks of BLOCK samples each."""
    n = N_BLOCKS * BLOCK
    block = np.concatenate([np.repeat(np.arange(N_BLOCKS) + i * N_BLOCKS, BLOCK) for i in range(n_rec)])
    fold = block % 2
    rec = np.repeat(np.arange(n_rec), n)
    return fold, block, rec


@dataclasses.dataclass
class Cand:
    name: str
    ratio: float = 0.5
    p: float = 1e-9
    fold_ratios: tuple = (0.5, 0.5)
    setting: tuple = (None, None)
    veto: str | None = None
    discrimination: str | None = None
    term: object = dataclasses.field(default_factory=lambda: types.SimpleNamespace(group=""))


def _run_separate(xa, xb, e):
    fold, block, rec = layout()
    a, b = Cand("asymmetric_hysteresis"), Cand("sensor_nonlinearity")
    cols = {"asymmetric_hysteresis": xa[:, None], "sensor_nonlinearity": xb[:, None]}

    def design(cands, f):
        return (np.zeros((e.size, 0)), np.zeros(0), np.zeros(0),
                [(cols[c.name], np.array([-np.inf]), np.array([np.inf])) for c in cands])

    return separate(a, [a, b], design, e, fold, block, rec, DT, 10_000)


def test_collinear_regressors_are_reported_as_a_pair():
    rng = np.random.default_rng(1)
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    xa = np.sin(2 * np.pi * 0.7 * t) ** 2
    xb = xa + 1e-4 * rng.standard_normal(n)          # the same regressor up to far below the noise
    e = 0.5 * xa + 0.01 * rng.standard_normal(n)
    (r,) = _run_separate(xa, xb, e)
    assert r["named_alone"]["significant"] and r["alternative_alone"]["significant"]
    assert not r["named_beyond"]["significant"] and not r["alternative_beyond"]["significant"]
    assert r["verdict"] == "inseparable"
    fields, text = separation_doc("asymmetric_hysteresis", [r])
    assert [a["name"] for a in fields["alternatives"]] == ["sensor_nonlinearity"]
    assert "cannot tell it from sensor_nonlinearity" in text
    doc = {"effects": [{"name": "asymmetric_hysteresis", "significant": True, **fields}]}
    (line,) = inseparable_lines(doc)
    assert line.startswith("asymmetric_hysteresis or sensor_nonlinearity (the data cannot tell them apart; record ")


def test_separable_regressors_are_not_a_pair():
    rng = np.random.default_rng(2)
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    xa = np.sin(2 * np.pi * 0.7 * t) ** 2
    xb = np.sign(np.sin(2 * np.pi * 0.23 * t))       # another shape; the residual holds both
    e = 0.5 * xa + 0.3 * xb + 0.01 * rng.standard_normal(n)
    (r,) = _run_separate(xa, xb, e)
    assert r["verdict"] == "both"
    fields, text = separation_doc("asymmetric_hysteresis", [r])
    assert fields["alternatives"] == [] and text == ""
    # the alternative alone explains part, the named one all: "a" (the named one is kept, no pair)
    e2 = 0.5 * xa + 0.01 * rng.standard_normal(n)
    xb2 = xa + 0.5 * np.sin(2 * np.pi * 3.1 * t)       # correlated with xa, but not the same
    (r2,) = _run_separate(xa, xb2, e2)
    assert r2["named_beyond"]["significant"] and r2["verdict"] in ("a", "neither")


def test_pair_verdicts():
    s, ns = {"significant": True}, {"significant": False}
    assert pair_verdict(ns, ns, s, s) == "inseparable"
    assert pair_verdict(s, ns, s, s) == "a"
    assert pair_verdict(ns, s, s, s) == "b"
    assert pair_verdict(s, s, s, s) == "both"
    assert pair_verdict(ns, ns, s, ns) == "neither"


def test_beyond_test_no_correction_is_not_significant():
    fold, block, rec = layout()
    e = np.random.default_rng(3).standard_normal(fold.size)
    r = beyond_test(e, np.zeros_like(e), np.zeros_like(e), fold, block, rec, DT)
    assert not r["significant"] and r["p"] == 1.0


def _offset_designs(e, n_rec, session_cols):
    """Designs of ``offset_level_test``: no nuisance, the offset columns of ``session_cols`` (per recording: its
    session column or -1)."""
    n = e.size // n_rec
    m = max(session_cols) + 1
    O = np.zeros((e.size, m))
    for i, g in enumerate(session_cols):
        if g >= 0:
            O[i * n:(i + 1) * n, g] = 1.0
    groups = {"sensor_offset": (O, np.full(m, -np.inf))}
    d = (np.zeros((e.size, 0)), np.zeros(0), np.zeros(0), groups)
    return [d, d]


def _misfit(level_rms, h=16):
    return {"mse_um2": {"level": level_rms ** 2, "slow": 0.0, "fast": 0.0}, "histories": [{}] * h, "slow_hz": 1.0}


def test_offset_within_the_base_level_misfit_is_refused_and_a_large_one_kept():
    rng = np.random.default_rng(4)
    fold, block, rec = layout(2)
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    u = 60 + 50 * np.sin(2 * np.pi * 0.5 * t)   # drive [V] of each recording
    levels = [np.zeros((2 * n, 0))] * 2
    # recording 1 in another session: a drive-dependent misfit (gain 2 %, off the calibration's centre 80 V)
    # whose mean over the session is -0.4 um, beside a base whose held-out level misfit is 0.3 um RMS
    e = np.concatenate([0.01 * rng.standard_normal(n), 0.02 * (u - 80.0) + 0.01 * rng.standard_normal(n)])
    designs = _offset_designs(e, 2, [-1, 0])
    r = offset_level_test(designs, levels, [e, e], fold, block, rec, DT, 10_000, _misfit(0.3))
    assert r["offset_um"][0] == pytest.approx(-0.4, abs=0.02)
    assert r["within_base_misfit"] and r["refused"]
    # the same session with a 3 um offset: beyond 2.95 x 0.3 um, kept
    e2 = e.copy()
    e2[n:] -= 3.0
    r2 = offset_level_test(designs, levels, [e2, e2], fold, block, rec, DT, 10_000, _misfit(0.3))
    assert r2["offset_um"][0] == pytest.approx(-3.4, abs=0.02)
    assert not r2["within_base_misfit"] and not r2["refused"]
    assert r2["quantile"] == pytest.approx(2.947, abs=0.01)   # t, 15 dof, two-sided 1 %


def test_offset_level_dependence_is_measured():
    rng = np.random.default_rng(5)
    fold, block, rec = layout(2)
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    u = 60 + 50 * np.sin(2 * np.pi * 0.5 * t)
    lev = np.zeros((2 * n, 2))
    lev[n:, 0] = u - u.mean()
    lev[n:, 1] = u - u.mean()
    e_slope = np.concatenate([0.01 * rng.standard_normal(n), -1.0 + 0.02 * (u - u.mean())
                              + 0.01 * rng.standard_normal(n)])
    e_const = np.concatenate([0.01 * rng.standard_normal(n), -1.0 + 0.01 * rng.standard_normal(n)])
    designs = _offset_designs(e_slope, 2, [-1, 0])
    r = offset_level_test(designs, [lev, lev], [e_slope, e_slope], fold, block, rec, DT, 10_000, _misfit(0.01))
    assert r["depends_on_level"]
    r0 = offset_level_test(designs, [lev, lev], [e_const, e_const], fold, block, rec, DT, 10_000, _misfit(0.01))
    assert not r0["depends_on_level"] and not r0["refused"]


def _slew_case(below_too, limit_adds=True):
    """A slew candidate's held-out figures: one fast step per block (beyond the limit) and a slow ramp (below it).
    ``below_too``: the candidate also takes a slow oscillation everywhere, which the term's refit of the dynamics
    alone (no limit) takes as well; ``limit_adds``: the limit then still takes the steps' ring beyond that refit."""
    rng = np.random.default_rng(6)
    fold, block, rec = layout()
    n = N_BLOCKS * BLOCK
    u = np.zeros(n)
    step_at = np.arange(BLOCK // 2, n, BLOCK)           # one fast step per block, slow ramps between
    for k in step_at:
        u[k:] += 5.0 * (1 if (k // BLOCK) % 2 else -1)
    u += 0.001 * np.arange(n)
    limit = 1e3   # [V/s]: the steps (5 V in one sample, 5000 V/s) exceed it, the ramp (1 V/s) does not
    ring = np.zeros(n)
    for k in step_at:
        ring[k:k + 40] = np.exp(-np.arange(min(40, n - k)) / 10.0)
    slow = 0.5 * np.sin(2 * np.pi * 3.0 * np.arange(n) * DT) if below_too else np.zeros(n)
    e = ring + slow + 0.01 * rng.standard_normal(n)
    correction = ring + slow + 0.002 * rng.standard_normal(n)
    p_refit = slow + 0.002 * rng.standard_normal(n)
    p_both = p_refit + (ring if limit_adds else 0.0)
    return check_slew_absent((e, correction, fold, block, rec, e, p_refit, p_both), [u], DT, limit, nperseg=50)


def test_slew_improvement_absent_below_the_limit_passes():
    r = _slew_case(False)
    assert r["testable"] and r["passed"], r
    assert r["figures"]["p_improvement_below"] >= 0.01


def test_slew_improvement_below_the_limit_passes_when_the_limit_adds_beyond_its_refit():
    r = _slew_case(True, limit_adds=True)
    assert r["passed"] and r["figures"]["p_improvement_below"] < 0.01 and r["figures"]["p_beyond_refit"] < 0.01


def test_slew_improvement_below_the_limit_fails_when_the_refit_takes_it_all():
    r = _slew_case(True, limit_adds=False)
    assert r["testable"] and not r["passed"]
    assert "does not act" in r["reason"] and r["figures"]["p_improvement_below"] < 0.01
    assert r["figures"]["p_beyond_refit"] >= 0.01


def test_bench_counts_truth_in_pair_separately():
    row = {"truth": ["sensor_nonlinearity"], "named": ["asymmetric_hysteresis"],
           "pair": ["asymmetric_hysteresis", "sensor_nonlinearity"]}
    assert ambiguous(row)
    assert ambiguous({**row, "named": ["sensor_nonlinearity"], "pair": ["sensor_nonlinearity", "saturation"]})
    assert not ambiguous({**row, "pair": []})
    assert not ambiguous({**row, "pair": ["asymmetric_hysteresis", "saturation"]})



def test_slew_shape_check_with_no_bin_below_unity_does_not_fail():
    """Development null s107-007 crashed here: every informative bin below the limit had |T| above 1, so the
    delay and bandwidth shapes had nothing to fit (not testable), which must neither raise nor refuse."""
    from piezoctl.diagnose.signature import Transfer, check_bandwidth, check_delay
    f = np.array([10.0, 20.0, 30.0])
    tr = Transfer(f=f, T=np.full(3, 2.0 + 0j), g2=np.full(3, 0.99), var=np.full(3, 1e-6), n_d=20, df=10.0,
                  segments=20)
    for r in (check_delay(tr, 1.0, 5.0, 1e-4), check_bandwidth(tr, 1.0, 5.0, 1e-4)):
        assert not r["testable"] and r["passed"]


def _run_beyond_pair(xa, xb, e, flag):
    """``separate`` of two terms that act only beyond the calibrated range (``flag``) or of two others."""
    fold, block, rec = layout()

    def term():
        return types.SimpleNamespace(group="", only_beyond_calibrated_range=flag)

    a, b = Cand("asymmetric_hysteresis", term=term()), Cand("saturation", term=term())
    cols = {"asymmetric_hysteresis": xa[:, None], "saturation": xb[:, None]}

    def design(cands, f):
        return (np.zeros((e.size, 0)), np.zeros(0), np.zeros(0),
                [(cols[c.name], np.array([-np.inf]), np.array([np.inf])) for c in cands])

    (r,) = separate(a, [a, b], design, e, fold, block, rec, DT, 10_000)
    return r


def test_two_beyond_range_terms_must_add_a_named_effects_size_beyond_each_other():
    """Round 21: two shapes that share most of the residual, each adding a little (significantly, fold ratios about
    0.86) beyond the other: "both" for any two terms, a pair when both act only beyond the calibrated range; two
    shapes that each add a named effect's size beyond the other stay "both" either way."""
    rng = np.random.default_rng(5)
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    c = np.sin(2 * np.pi * 0.7 * t) ** 2
    d1, d2 = np.sign(np.sin(2 * np.pi * 0.23 * t)), np.sin(2 * np.pi * 1.9 * t)
    xa, xb = c + 0.05 * d1, c + 0.05 * d2
    e = 0.5 * (xa + xb) + 0.05 * rng.standard_normal(n)
    other = _run_beyond_pair(xa, xb, e, False)
    edge = _run_beyond_pair(xa, xb, e, True)
    for r in (other, edge):
        assert r["named_beyond"]["p"] < 1e-6 and r["alternative_beyond"]["p"] < 1e-6
        assert 0.8 < max(r["named_beyond"]["fold_ratios"]) < 0.9
        assert 0.8 < max(r["alternative_beyond"]["fold_ratios"]) < 0.9
    assert other["verdict"] == "both" and "beyond_size_max" not in other
    assert edge["verdict"] == "inseparable" and edge["beyond_size_max"] == 0.8
    fields, _ = separation_doc("asymmetric_hysteresis", [edge])
    assert [a["name"] for a in fields["alternatives"]] == ["saturation"]
    # distinct shapes, each a large part of the residual: both, with or without the size
    xb2 = np.sign(np.sin(2 * np.pi * 0.23 * t))
    e2 = 0.5 * c + 0.3 * xb2 + 0.01 * rng.standard_normal(n)
    r2 = _run_beyond_pair(c, xb2, e2, True)
    assert max(r2["named_beyond"]["fold_ratios"]) <= 0.8 and max(r2["alternative_beyond"]["fold_ratios"]) <= 0.8
    assert r2["verdict"] == "both"
    # one shape the residual holds, the other a part of it: only the first adds beyond the other ("a"); the size is
    # asked only of "both"
    xb3 = c + 0.5 * np.sin(2 * np.pi * 3.1 * t)
    e3 = 0.5 * c + 0.01 * rng.standard_normal(n)
    r3 = _run_beyond_pair(c, xb3, e3, True)
    assert r3["verdict"] == "a" and "beyond_size_max" not in r3



def _slew_case_below_fit(fast_below, limit_adds):
    """Round 27: a slew candidate whose refit of the dynamics is the current model's (the limit did not act on the
    calibration: the check's refit step is then the term's own test) and which also takes a lag present at every
    rate. ``fast_below``: the drive also runs a 10 Hz sine at 0.7 of the limit, below it, where the nested
    corrections fitted below the limit take that lag; ``limit_adds``: the limit still takes the steps' ring beyond
    them."""
    rng = np.random.default_rng(7)
    fold, block, rec = layout()
    n = N_BLOCKS * BLOCK
    t = np.arange(n) * DT
    u = np.zeros(n)
    step_at = np.arange(BLOCK // 2, n, BLOCK)
    for k in step_at:
        u[k:] += 5.0 * (1 if (k // BLOCK) % 2 else -1)
    limit = 1e3   # [V/s]
    if fast_below:
        u += 0.7 * limit / (2 * np.pi * 10.0) * np.sin(2 * np.pi * 10.0 * t)
    ring = np.zeros(n)
    for k in step_at:
        ring[k:k + 40] = np.exp(-np.arange(min(40, n - k)) / 10.0)
    lag = 0.5 * np.cos(2 * np.pi * 10.0 * t)
    e = ring + lag + 0.01 * rng.standard_normal(n)
    correction = ring + lag + 0.002 * rng.standard_normal(n)
    q_small = lag + 0.002 * rng.standard_normal(n)
    q_big = q_small + (limit_adds * ring)
    return check_slew_absent((e, correction, fold, block, rec, e, np.zeros(n), correction, q_small, q_big), [u], DT,
                             limit, nperseg=50)


def test_slew_fails_when_the_corrections_fitted_below_the_limit_leave_it_nothing():
    """Null s137-036: a lag at every rate, taken above the limit by the term; the corrections fitted where the limit
    does not act (the drive runs there at 0.7 of the limit) take it, and the limit adds nothing beyond them."""
    r = _slew_case_below_fit(fast_below=True, limit_adds=False)
    assert r["testable"] and not r["passed"], r
    assert r["figures"]["p_beyond_refit"] < 0.01 and r["figures"]["p_beyond_below_fit"] >= 0.01
    assert "same below the limit" in r["reason"]


def test_slew_fails_when_it_adds_beyond_the_corrections_fitted_below_the_limit_less_than_an_effects_size():
    """s137-036 in the second form: beside the corrections the limit added 0.4 and 3.4 %, at p 6.4e-3: significant,
    not an effect."""
    r = _slew_case_below_fit(fast_below=True, limit_adds=0.05)
    assert r["testable"] and not r["passed"], r
    assert r["figures"]["p_beyond_below_fit"] < 0.01 and min(r["figures"]["fold_ratios_beyond_below_fit"]) > 0.8


def test_slew_passes_when_it_adds_beyond_the_corrections_fitted_below_the_limit():
    r = _slew_case_below_fit(fast_below=True, limit_adds=True)
    assert r["passed"], r
    assert r["figures"]["p_beyond_below_fit"] < 0.01


def test_slew_below_fit_not_tested_where_the_drive_below_the_limit_is_slow():
    """A true limit's recordings run below it only slowly (triangles, dwells): the corrections fitted there say
    nothing about fast motion, and the check keeps its round-11 verdict."""
    r = _slew_case_below_fit(fast_below=False, limit_adds=False)
    assert r["passed"], r
    assert r["figures"]["p_improvement_below"] < 0.01 and r["figures"]["p_beyond_refit"] < 0.01
    assert "p_beyond_below_fit" not in r["figures"]
    assert r["figures"]["below_rate_top_v_per_s"] < 0.5 * 1e3


def test_below_limit_ahead_drops_the_rise_to_the_limit():
    """Round 27: a drive whose rate rises through the limit runs just below it for a few samples before the limit
    acts (held-out s135-055, s136-008: 0.97 of the limit, which made the corrections' test run on recordings whose
    other rows below the limit are slow); with ``ahead`` those samples are left out as the samples after are."""
    from piezoctl.diagnose.signature import below_limit
    dt, limit, n = 1e-3, 1e3, 20
    rate = np.concatenate([np.full(200, 10.0), np.linspace(10.0, 3e3, 100), np.full(100, 3e3), np.full(300, 0.0)])
    u = np.cumsum(rate) * dt
    plain = below_limit([u], dt, limit, n, limited=True)[0]
    ahead = below_limit([u], dt, limit, n, limited=True, ahead=True)[0]
    du = np.abs(np.diff(u, prepend=u[0])) / dt
    assert np.max(du[plain]) > 0.9 * limit                 # the rise to the limit counted below it
    assert np.max(du[ahead]) < 0.9 * limit and np.all(ahead <= plain)
    assert np.all(ahead[:150])                           # the slow start stays
