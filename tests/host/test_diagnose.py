"""piezoctl diagnose: contract files, both models through `simulate --model`, and a fast subset of the
concealed-effect cases built with the C stage model (docs/diagnose.md)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from piezoctl.diagnose.cases import FAST_CASES, make_case
from piezoctl.ident.terms import VOCABULARY
from piezoctl.diagnose.run import diagnose
from piezoctl.ident import refined
from piezoctl.io.recording import load_recording

try:
    from piezoctl.sil.stage import find_library
    find_library()
    HAVE_STAGE = True
except Exception:  # noqa: BLE001 - library not built
    HAVE_STAGE = False

pytestmark = pytest.mark.skipif(not HAVE_STAGE, reason="libpiezo_stage.so not built")
ROOT = Path(__file__).resolve().parents[2]


def _cli(*args):
    return subprocess.run([str(ROOT / "tools" / "piezoctl"), *map(str, args)], capture_output=True, text=True)


def test_slew_limit_matches_a_plain_loop():
    rng = np.random.default_rng(1)
    u = np.cumsum(rng.normal(0, 1, 2000)) + np.repeat(rng.uniform(-50, 50, 20), 100)
    out = refined.slew_limit(u, 0.7)
    ref = u.copy()
    for i in range(1, u.size):
        ref[i] = ref[i - 1] + np.clip(u[i] - ref[i - 1], -0.7, 0.7)
    assert np.max(np.abs(out - ref)) < 1e-12


def test_bouc_wen_is_rate_independent():
    t = np.linspace(0, 1, 4001)
    v = 0.8 * np.sin(2 * np.pi * 2 * t)
    h1 = refined.bouc_wen_h(v, 3.0, 0.9)
    h2 = refined.bouc_wen_h(v[::4], 3.0, 0.9)
    assert np.max(np.abs(h1[::4] - h2)) < 5e-3 * np.ptp(h1)
    assert np.ptp(h1) > 0.1


def test_bouc_wen_large_step_crosses_zero_exactly():
    # one 1.6-wide step (h crosses zero inside it) must equal the same path taken in 4000 small steps
    v_small = np.concatenate([np.full(10, 0.8), np.linspace(0.8, -0.8, 4001)[1:]])
    v_big = np.concatenate([np.full(10, 0.8), [-0.8]])
    for beta, gamma in ((3.0, 0.9), (8.0, 2.0), (2.0, -1.2)):
        pre = np.linspace(-0.8, 0.8, 2001)
        h_small = refined.bouc_wen_h(np.concatenate([pre, v_small]), beta, gamma, -0.8)
        h_big = refined.bouc_wen_h(np.concatenate([pre, v_big]), beta, gamma, -0.8)
        assert h_small[2000 + 9] > 0.1 / beta      # h > 0 before the step
        assert h_big[-1] < 0
        assert abs(h_big[-1] - h_small[-1]) < 1e-9


@pytest.mark.parametrize("name", FAST_CASES)
def test_concealed_case(tmp_path, name):
    case = make_case(name, tmp_path / "case", scale=0.6, seed=3)
    out = tmp_path / "out"
    r = _cli("diagnose", "--calibration", *case["calibration"], "--recordings", *case["recordings"],
             "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "diagnosis.json").read_text())
    assert (out / "report.html").stat().st_size > 10_000
    eff = doc["effects"]
    assert eff and all(x["name"] in VOCABULARY + ("none",) for x in eff)
    for x in eff:
        assert {"name", "significant", "evidence", "where", "params", "improvement"} <= set(x)
        assert {"nrmse_before", "nrmse_after"} <= set(x["improvement"])
    truth = case["truth"][0] if case["truth"] else "none"
    assert eff[0]["name"] == truth
    h = doc["fit"]["heldout"]
    if truth == "none":
        assert not any(x["significant"] for x in eff)
        assert doc["fit"]["refined"]["nrmse"] == pytest.approx(doc["fit"]["base"]["nrmse"])
    else:
        assert eff[0]["significant"]
        assert h["refined_nrmse"] <= 0.7 * h["base_nrmse"]
    # an improvement is reported only where the exact refined model's held-out error went down
    for x in eff:
        assert x["improvement"]["nrmse_after"] <= x["improvement"]["nrmse_before"]
        if x["significant"]:
            assert max(x["improvement"]["exact_fold_ratios"]) < 1.0
    # both model files run through `simulate --model`
    for key in ("base_model", "refined_model"):
        p = out / doc[key]
        sim = tmp_path / f"{key}.csv"
        r = _cli("simulate", "--model", p, "--input", case["recordings"][0], "--out", sim)
        assert r.returncode == 0, r.stderr
        y = np.loadtxt(sim, delimiter=",", skiprows=1)[:, 1]
        rec = load_recording(case["recordings"][0])
        assert y.shape == rec.y.shape and np.all(np.isfinite(y))


def test_bad_input_is_a_cli_error(tmp_path):
    r = _cli("diagnose", "--calibration", tmp_path / "missing.csv", "--recordings", tmp_path / "x.csv",
             "--out", tmp_path / "o")
    assert r.returncode == 2 and "missing.csv" in r.stderr


def test_active_block_test_finds_a_localized_improvement_and_not_noise():
    from piezoctl.diagnose.significance import active_block_test
    rng = np.random.default_rng(4)
    nb, m = 40, 500
    blocks = np.repeat(np.arange(nb), m)
    noise = rng.normal(0, 1.0, nb * m)
    # an effect in 8 of 40 blocks, 3x the noise; the term predicts it (correction) and removes it
    eff = np.zeros(nb * m)
    act = np.isin(blocks, np.arange(0, nb, 5))
    eff[act] = 3.0 * np.sin(np.arange(np.sum(act)) * 0.05)
    t, p, n = active_block_test(noise + eff, noise, eff, blocks)
    assert n == 8 and p < 1e-4
    # a term that predicts the same correction but the data do not contain the effect: no evidence
    t, p, n = active_block_test(noise, noise - eff, eff, blocks)
    assert p > 0.5


def test_units_follow_the_residual_energy_correlation_time():
    from piezoctl.diagnose.significance import UNIT_MIN_S, test_units
    rng = np.random.default_rng(7)
    dt, m, nb = 1e-4, 6000, 6
    blocks = np.repeat(np.arange(nb), m)
    rec = np.zeros(nb * m, int)
    # a slow misfit (the error follows the history for seconds): one unit per block, as before round 8
    slow = np.cumsum(rng.normal(0, 1, nb * m))
    u = test_units(slow, blocks, rec, dt)
    assert np.array_equal(np.unique(u), np.arange(nb))
    # short rings after steps every 0.05 s plus noise: several units per block, each at least UNIT_MIN_S
    ring = rng.normal(0, 0.1, nb * m)
    for k0 in range(0, nb * m, 500):
        k = np.arange(min(200, nb * m - k0))
        ring[k0 + k] += np.exp(-k / 40) * np.sin(2 * np.pi * k / 10)
    u = test_units(ring, blocks, rec, dt)
    per_block = [np.unique(u[blocks == b]).size for b in range(nb)]
    assert min(per_block) >= 4 and max(per_block) <= int(round(m * dt / UNIT_MIN_S))
    # a constant correction (a level) is fully correlated: one unit per block whatever the residual
    u = test_units(ring, blocks, rec, dt, correction=np.full(ring.size, 0.3))
    assert np.array_equal(np.unique(u), np.arange(nb))
    # units never straddle blocks
    assert all(np.unique(blocks[u == k]).size == 1 for k in np.unique(u))


def _rings(seed, per_block):
    """Rings after steps every 0.1 s in 8 blocks of 0.6 s; the term leaves a part of each ring, drawn per ring
    (independent events) or per block (rings of one block improve together)."""
    rng = np.random.default_rng(seed)
    dt, m, nb = 1e-4, 6000, 8
    blocks = np.repeat(np.arange(nb), m)
    noise = rng.normal(0, 0.1, nb * m)
    eff, kept = np.zeros(nb * m), np.zeros(nb * m)
    how_well = rng.uniform(0.2, 1.1, nb)
    for k0 in range(0, nb * m, 1000):
        k = np.arange(300)
        eff[k0 + k] = np.exp(-k / 60) * np.sin(2 * np.pi * k / 12)
        kept[k0 + k] = how_well[k0 // m] if per_block else rng.uniform(0.0, 1.3)
    return dt, blocks, noise, eff, kept


def test_units_pool_independent_events_and_not_blocks_that_move_together():
    from piezoctl.diagnose.significance import active_block_test, test_units
    for per_block in (False, True):
        dt, blocks, noise, eff, kept = _rings(0, per_block)
        rec = np.zeros(blocks.size, int)
        before, after = noise + eff, noise + kept * eff
        _, p_blocks, n_blocks = active_block_test(before, after, before - after, blocks)
        units = test_units(before, blocks, rec, dt)
        _, p_units, n_units = active_block_test(before, after, before - after, blocks, units)
        assert n_blocks == 8
        if not per_block:   # ~48 independent rings: far more evidence than 8 blocks
            assert n_units > 30 and p_units < 1e-4 and p_units < p_blocks / 20
        else:               # rings of a block improve together: the design effect keeps the blocks' evidence
            assert p_units > p_blocks / 3
    # the same units give no evidence to a term that predicts rings the data do not have
    _, p_null, _ = active_block_test(noise, noise - 0.7 * eff, 0.7 * eff, blocks,
                                     test_units(noise, blocks, rec, dt))
    assert p_null > 0.5


def test_outside_mask_guards_after_the_excursion():
    from piezoctl.diagnose.run import OUT_GUARD_S, _outside_mask
    from piezoctl.diagnose.select import Signals
    dt = 1e-4
    u = np.full(20000, 50.0)
    u[5000:6000] = 120.0
    z = np.zeros(u.size)
    s = Signals(name="r", t=np.arange(u.size) * dt, u=u, y=z, u2=None, x2=None, temp=None, dt=dt, v=z, h=z, hyst=z,
                yb=z, ydyn=z)
    m = _outside_mask(s, 10.0, 100.0)
    g = int(round(OUT_GUARD_S / dt))
    assert not m[:5000].any() and m[5000:6000 + g - 1].all() and not m[6000 + g + 1:].any()


def test_discriminate_group_prefers_the_clearly_smaller_residual_and_states_ambiguity():
    from piezoctl.diagnose.discriminate import discriminate_group
    rng = np.random.default_rng(5)
    nb, m = 24, 400
    blocks = np.repeat(np.arange(nb), m)
    fold = blocks % 2
    cands = [type("C", (), {"name": n})() for n in ("amplifier_bandwidth", "delay")]
    small = rng.normal(0, 1.0, nb * m)
    large = rng.normal(0, 2.0, nb * m)
    order, text = discriminate_group(cands, [large, small], fold, blocks, 100.0)
    assert order == [1, 0] and text.startswith("Discrimination") and "delay" in text
    same = [rng.normal(0, 1.0, nb * m), rng.normal(0, 1.0, nb * m)]
    order, text = discriminate_group(cands, same, fold, blocks, 100.0)
    assert order == [0, 1] and text.startswith("Ambiguous")


def test_dynamics_plausibility_rejects_gain_beyond_the_calibration_band():
    from scipy import signal as sps
    from piezoctl.ident.base import plausible
    # a 600 Hz mode at 10 kHz inside a band reaching 1 kHz: accepted
    b, a, _ = sps.cont2discrete(([(2 * np.pi * 600) ** 2], [1, 2 * 0.03 * 2 * np.pi * 600, (2 * np.pi * 600) ** 2]),
                                1e-4, method="zoh")
    assert plausible((np.ravel(b), np.ravel(a)), 0.1)
    # the same mode when the calibration reached only 20 Hz (0.002 cycles/sample): |G| = 16 at 600 Hz, rejected
    assert not plausible((np.ravel(b), np.ravel(a)), 0.002)
    # the ARX a 20 Hz calibration produced (|G| = 27 at Nyquist): rejected; a static G always accepted
    assert not plausible((np.array([-10.1278, 21.4652, -11.336]), np.array([1.0, -0.7907, -0.208])), 0.002)
    assert plausible((np.array([1.0]), np.array([1.0])), 0.002)


def test_drive_discontinuities_flag_jumps_not_smooth_drives():
    from piezoctl.diagnose.locate import drive_discontinuities
    fs = 10_000.0
    t = np.arange(20001) / fs
    # the valve's inverse runs: a 50 Hz sine, then the last sample back at the start (-95 -> -1.78 V)
    u = -48.4 - 46.6 * np.cos(2 * np.pi * 50 * t)          # ends at -95 V
    u[-1] = -1.78
    j = drive_discontinuities(t, u)
    assert len(j) == 1
    assert j[0]["sample"] == u.size - 1 and j[0]["where"] == "last sample"
    assert j[0]["u_after_v"] == -1.78 and j[0]["jump_v"] == pytest.approx(-1.78 - u[-2])
    # smooth drives, however fast, have none: a 1 kHz sine, a triangle, a chirp
    tri = 2 * np.abs(((t * 5) % 1) - 0.5) * 100
    chirp = 50 * np.sin(2 * np.pi * (5 * t + 0.5 * (1000 - 5) / 2 * t ** 2))
    for smooth in (50 * np.sin(2 * np.pi * 1000 * t), tri, chirp):
        assert drive_discontinuities(t, smooth) == []
    # steps are jumps (each one), a small one below 5 % of the span is not
    steps = np.repeat([0.0, 80.0, 20.0, 22.0, 100.0], 4000)
    ts = np.arange(steps.size) / fs
    assert [x["sample"] for x in drive_discontinuities(ts, steps)] == [4000, 8000, 16000]


def test_residual_autocorrelation_band_holds_white_noise_and_not_a_sine():
    from piezoctl.diagnose.locate import residual_autocorrelation
    rng = np.random.default_rng(0)
    dt = 1e-4
    lag, ac, bound = residual_autocorrelation(rng.normal(size=100_000), dt)
    assert ac[0] == pytest.approx(1.0) and lag[1] == pytest.approx(1e-3)   # decimated to 1 kHz
    assert bound == pytest.approx(2.58 / np.sqrt(10_000))
    assert np.mean(np.abs(ac[1:]) > bound) <= 0.08
    t = np.arange(100_000) * dt
    _, ac_s, b_s = residual_autocorrelation(np.sin(2 * np.pi * 7 * t), dt)
    assert np.mean(np.abs(ac_s[1:]) > b_s) > 0.9


def test_where_and_discontinuities_read_as_table_rows():
    from piezoctl.diagnose.report import discontinuity_rows, where_rows
    where = {"recordings": [{"recording": "rec1.csv", "share": 0.41}],
             "time_windows": [{"t0_s": 0.5, "t1_s": 1.25, "rms_um": 0.012, "x_median": 3.1, "recording": "rec1.csv"}],
             "frequency_bands": [{"f_lo_hz": 0.0, "f_hi_hz": 1.0, "share": 0.7}],
             "amplitude_v": [10.0, 40.0], "rate_v_per_s": [0.0, 120.0]}
    rows = dict(where_rows(where))
    assert rows["recordings (share of the term's energy)"] == "rec1.csv 41 %"
    assert rows["time window [s] in rec1.csv"] == "0.50 - 1.25 (12.0 nm RMS, 3.1 x the median window)"
    assert rows["drive where it acts most [V]"] == "10.0 - 40.0"
    dd = [{"file": "/x/valve.csv", "role": "recording", "count": 1,
           "jumps": [{"sample": 20000, "t_s": 2.0, "u_before_v": -95.05, "u_after_v": -1.78, "jump_v": 93.27,
                      "where": "last sample"}]}]
    assert discontinuity_rows(dd) == [["valve.csv", "recording", "1", "20000", "2.0000", "-95.05 -> -1.78",
                                       "+93.27", "last sample"]]


def test_drive_side_terms_offer_nothing_within_the_loops_own_latency():
    """A lag of two sample periods or less is the sampled loop's own latency: no delay or amplifier bandwidth
    setting (grid or refinement) is that small, so a null stage's one-sample latency cannot be named."""
    from piezoctl.ident.terms import LATENCY_SAMPLES, TERMS
    ctx = type("Ctx", (), {"dt": 1e-4})()
    assert min(TERMS["delay"].settings(ctx)) > LATENCY_SAMPLES
    bw = TERMS["amplifier_bandwidth"]
    grid = bw.settings(ctx)
    finer = [f for lvl in (1, 2) for g in grid for f in bw.refine(ctx, g, lvl)]
    assert grid and finer
    assert all(1.0 / (2 * np.pi * f) > LATENCY_SAMPLES * ctx.dt for f in grid + finer)
    # without the rule the grid reaches 2.5 kHz (a 0.06 ms lag): the test can fail
    assert max(grid) < 1.0 / (2 * np.pi * LATENCY_SAMPLES * ctx.dt) < 2500.0


def test_bandwidth_offers_no_corner_inside_the_identified_band():
    """Round 19: a pole whose corner lies inside the band the base identified its dynamics in acted on the
    calibration there and is in G (the term's refit takes it again); its corner is offered above that band only,
    the higher of the calibration's and the base's stated band, in the grid and in every refinement."""
    from piezoctl.ident.terms import TERMS
    bw = TERMS["amplifier_bandwidth"]
    free = bw.settings(type("Ctx", (), {"dt": 1e-4})())
    for cal, dyn in ((300.0, 120.0), (120.0, 300.0), (45.0, None)):
        ctx = type("Ctx", (), {"dt": 1e-4, "cal_band_hz": cal, "dynamics_band_hz": dyn})()
        edge = max(cal, dyn or 0.0)
        grid = bw.settings(ctx)
        finer = [f for lvl in (1, 2) for g in grid for f in bw.refine(ctx, g, lvl)]
        assert grid and finer and bw.applicable(ctx)
        assert all(f > edge for f in grid + finer)
        assert grid == [f for f in free if f > edge]
        # the grid without the rule has corners inside the band: the test can fail
        assert min(free) < edge
    # development null s121-018: calibration band 548 Hz, the base's 1089 Hz; above it every corner's lag is
    # within the loop's latency (2 samples: below 796 Hz at 10 kHz), so the term is not offered at all
    s18 = type("Ctx", (), {"dt": 1e-4, "cal_band_hz": 548.0, "dynamics_band_hz": 1089.0})()
    assert any(f < 1089.0 for f in free)
    assert bw.settings(s18) == [] and not bw.applicable(s18)
