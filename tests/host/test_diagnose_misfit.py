"""The base's misfit on held-out calibration histories as the candidates' nuisance (diagnose/misfit.py,
ident/base.py ``_holdout_histories``; docs/diagnose.md, round 9)."""

import numpy as np

from piezoctl.diagnose.misfit import base_misfit, credited_ratio, split_bands
from piezoctl.ident.base import fit_base, history_holdout
from piezoctl.io.recording import Recording

FS = 10_000.0
DT = 1.0 / FS


def test_bands_sum_to_the_residual_and_separate_level_slow_and_fast():
    t = np.arange(int(8 * FS)) * DT
    lvl, slow, fast = 0.3, 0.2 * np.sin(2 * np.pi * 0.125 * t), 0.1 * np.sin(2 * np.pi * 40 * t)
    parts = split_bands(lvl + slow + fast, DT, 1.0)
    assert np.allclose(parts.sum(axis=0), lvl + slow + fast)
    assert abs(parts[0, 0] - lvl) < 0.01                       # a whole number of slow periods: mean ~ level
    assert np.sqrt(np.mean((parts[1] - slow) ** 2)) < 0.02     # filtfilt edges aside
    assert np.sqrt(np.mean((parts[2] - fast) ** 2)) < 0.02


def _misfit(level=0.0, slow=0.0, fast=0.0):
    return {"slow_hz": 1.0, "mse_um2": {"level": level, "slow": slow, "fast": fast}}


def test_credited_ratio_is_the_held_out_ratio_without_misfit_and_discounts_only_its_band():
    rng = np.random.default_rng(1)
    n = int(6 * FS)
    t = np.arange(n) * DT
    rec = np.repeat([0, 1], n // 2)
    noise = rng.normal(0, 0.01, n)
    level = np.where(rec == 0, 0.05, -0.05)
    fast = 0.1 * np.sin(2 * np.pi * 30 * t)
    e = level + fast + noise
    # a term that takes the level: without a misfit its credited ratio is its held-out ratio
    r0, _ = credited_ratio(e, level, rec, DT, None)
    assert abs(r0 - np.sqrt(np.mean((e - level) ** 2) / np.mean(e ** 2))) < 1e-9
    # the base's misfit on unseen histories holds a level as large: the level term is not credited
    r1, bands = credited_ratio(e, level, rec, DT, _misfit(level=0.05 ** 2))
    assert r1 > 0.99 and bands["level"]["improvement_um2"] > 0.9 * 0.05 ** 2
    # the same misfit says nothing about a fast correction, which keeps its credit
    r2, _ = credited_ratio(e, fast, rec, DT, _misfit(level=0.05 ** 2))
    r2_plain, _ = credited_ratio(e, fast, rec, DT, None)
    assert abs(r2 - r2_plain) < 0.02 and r2 < 0.8
    # a band the term makes worse is not forgiven: a level term that also adds a fast error
    r3, _ = credited_ratio(e, level + 0.05 * np.sin(2 * np.pi * 70 * t), rec, DT, _misfit(level=0.05 ** 2))
    assert r3 >= 1.0 - 1e-9


def _play(u, r):
    y = np.empty_like(u)
    p = 0.0
    for k, x in enumerate(u):
        p = min(max(p, x - r), x + r)
        y[k] = p
    return y


def test_held_out_histories_cost_more_than_seen_ones_and_cancel_what_both_contain():
    """On a two-play stage (thresholds off the plane's grid, so the base is not exact), the base's error on
    held-out quarters of its calibration exceeds its error on the same samples seen; an effect the whole
    calibration contains (a 0.1 um vibration at 7 Hz, which a hysteresis plane cannot fit) raises both, and the
    excess (the misfit the candidates are discounted by) grows much less than the error itself."""
    rng = np.random.default_rng(4)
    t = np.arange(int(10 * FS)) * DT

    def stage(v):
        return 10 * v + 3 * _play(v, 0.3) + 2 * _play(v, 0.7)

    u1 = 75 + 70 * np.sin(2 * np.pi * 1.3 * t) * np.exp(-t / 6)
    walk = np.cumsum(rng.normal(0, 1, t.size))
    walk = np.convolve(walk, np.ones(2000) / 2000, mode="same")
    u2 = 75 + 70 * (walk - walk.mean()) / np.max(np.abs(walk - walk.mean()))
    recs = [Recording(t=t, u=u, y=stage((u - 75) / 75) + rng.normal(0, 0.005, t.size)) for u in (u1, u2)]
    base = fit_base(recs, holdout=True)
    held = history_holdout(base)
    assert "_holdout" not in base and len(held) == 8
    m = base_misfit(held, ["a", "b"], DT, 1.0)
    assert m["rms_um"] > m["rms_seen_um"]
    assert abs(sum(m["mse_um2"].values()) - (m["rms_um"] ** 2 - m["rms_seen_um"] ** 2)) < 0.2 * m["rms_um"] ** 2
    recs_d = [Recording(t=r.t, u=r.u, y=r.y + 0.1 * np.sin(2 * np.pi * 7 * t)) for r in recs]
    md = base_misfit(history_holdout(fit_base(recs_d, holdout=True)), ["a", "b"], DT, 1.0)
    grew_seen = md["rms_seen_um"] ** 2 - m["rms_seen_um"] ** 2
    grew_excess = sum(md["mse_um2"].values()) - sum(m["mse_um2"].values())
    assert grew_seen > 0.003          # [um^2]: the vibration (0.005 um^2) is in the seen error
    assert grew_excess < 0.25 * grew_seen


def test_none_reports_the_base_residual_and_its_misfit_by_band():
    from types import SimpleNamespace

    from piezoctl.diagnose.run import _none_entry, residual_bands
    n = int(4 * FS)
    t = np.arange(n) * DT
    y = 0.2 + 0.05 * np.sin(2 * np.pi * 30 * t)
    sig = SimpleNamespace(y=y, yb=np.zeros(n))
    ctx = SimpleNamespace(signals=[sig], valid=[np.ones(n, bool)], dt=DT, misfit=_misfit(level=0.01 ** 2))
    bands = residual_bands(ctx)
    assert abs(bands["level_rms_um"] - 0.2) < 1e-6 and abs(bands["fast_rms_um"] - 0.05 / np.sqrt(2)) < 2e-3
    mf = {**_misfit(level=0.01 ** 2, fast=0.02 ** 2), "rms_um": 0.05, "rms_seen_um": 0.04}
    fit = {"base": {"nrmse": 0.01}}
    e = _none_entry([], fit, None, {"misfit": mf}, bands)
    assert e["name"] == "none" and e["where"]["residual"] is bands
    assert abs(e["where"]["base_misfit"]["fast_rms_um"] - 0.02) < 1e-12
    assert "did not see" in e["evidence"] and "0.0500 um RMS" in e["evidence"]


def test_peak_frequencies_with_a_recording_shorter_than_a_segment():
    """Residuals of different lengths (one shorter than 4096 samples) share one frequency grid: the
    mode's line is found, not a crash on spectra of different lengths."""
    import numpy as np
    from piezoctl.diagnose.locate import peak_frequencies
    dt = 1e-4
    rng = np.random.default_rng(3)
    t = np.arange(20000) * dt
    long_e = 1e-3 * rng.standard_normal(t.size) + 0.05 * np.sin(2 * np.pi * 1500.0 * t)
    short_e = 1e-3 * rng.standard_normal(1000) + 0.05 * np.sin(2 * np.pi * 1500.0 * t[:1000])
    peaks = peak_frequencies([long_e, short_e], dt)
    assert peaks and abs(peaks[0] - 1500.0) < 20.0, peaks
