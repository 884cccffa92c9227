"""A term that acts above the calibration's band is sized on the residual above it (round 16,
misfit.ratios_above): the base's slow misfit below the band neither helps nor hides it, and the base's fast misfit
is still subtracted from what it is credited with."""

import numpy as np

from piezoctl.diagnose import misfit
from piezoctl.ident.terms import TERMS

DT = 1e-4
N = 40_000


def _case(seed=3):
    """A residual: a large 2 Hz misfit (1 um) plus a 1.2 kHz ring (0.1 um) and noise; the correction is the ring."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    slow = np.sin(2 * np.pi * 2.0 * t)
    ring = 0.1 * np.sin(2 * np.pi * 1200.0 * t) * np.exp(-((t % 0.5) / 0.05))
    e = slow + ring + 0.002 * rng.standard_normal(N)
    fold = ((np.arange(N) * 8) // N) % 2
    rec = np.zeros(N, int)
    return e, ring, fold, rec


def _misfit(fast_um2):
    return {"slow_hz": 1.0, "mse_um2": {"level": 0.0, "slow": 0.0, "fast": fast_um2}}


def test_the_ring_is_sized_above_the_band_not_beside_the_slow_misfit():
    e, ring, fold, rec = _case()
    whole = [float(np.sqrt(np.sum((e - ring)[fold == f] ** 2) / np.sum(e[fold == f] ** 2))) for f in (1, 0)]
    assert min(whole) > 0.95          # beside the slow misfit the ring is too small for any size gate
    fr, cr = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, _misfit(0.0))
    assert max(fr) < 0.2 and cr < 0.2  # above 300 Hz it is nearly everything


def test_the_fast_misfit_is_still_subtracted():
    e, ring, fold, rec = _case()
    ring_mse = float(np.mean(ring ** 2))
    _, cr_small = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, _misfit(0.1 * ring_mse))
    _, cr_all = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, _misfit(2.0 * ring_mse))
    assert cr_small < 0.5
    assert cr_all > 0.99               # a fast misfit as large as the ring could explain all of it


def test_a_correction_that_is_wrong_above_the_band_is_not_helped():
    e, ring, fold, rec = _case()
    fr, cr = misfit.ratios_above(e, -ring, fold, rec, DT, 300.0, _misfit(0.0))
    assert min(fr) > 1.5 and cr >= 1.0


def test_no_edge_below_nyquist_no_figures():
    e, ring, fold, rec = _case()
    assert misfit.ratios_above(e, ring, fold, rec, DT, 0.5 / DT, None) == (None, None)


def test_only_the_mode_is_judged_above_the_calibration_band():
    assert TERMS["unmodeled_resonance"].acts_above_calibration
    assert not any(t.acts_above_calibration for n, t in TERMS.items() if n != "unmodeled_resonance")


def test_the_misfit_above_the_edge_is_measured_and_used():
    """base_misfit(edge_hz=...) measures the held-out histories' excess above the edge; ratios_above subtracts it
    (not the whole fast band's) when the edges agree."""
    e, ring, fold, rec = _case()
    t = np.arange(8000) * DT
    slow_gap = 0.3 * np.sin(2 * np.pi * 20.0 * t)       # a misfit above 1 Hz but below the edge
    fast_gap = 0.005 * np.sin(2 * np.pi * 900.0 * t)     # and a small one above it
    held = [{"resid": slow_gap + fast_gap, "resid_in": np.zeros(t.size), "scored": np.ones(t.size, bool),
             "recording": 0, "start": 0, "stop": t.size}]
    m = misfit.base_misfit(held, ["cal"], DT, 1.0, edge_hz=300.0)
    assert m["above_hz"] == 300.0
    assert abs(m["above_um2"] - 0.5 * 0.005 ** 2) < 0.1 * 0.5 * 0.005 ** 2
    assert m["mse_um2"]["fast"] > 100 * m["above_um2"]
    _, cr_above = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, m)
    _, cr_fast = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, dict(m, above_hz=350.0))
    assert cr_above < 0.5 < cr_fast   # the 20 Hz misfit would hide the ring; the one above the edge does not
    # round 17: a misfit measured above a lower edge (the calibration's) serves a higher one (the mode's own)
    _, cr_lower = misfit.ratios_above(e, ring, fold, rec, DT, 300.0, dict(m, above_hz=250.0))
    assert cr_lower == cr_above
    assert "above_um2" not in misfit.base_misfit(held, ["cal"], DT, 1.0)
