"""Round 19, the concealed mode: its damping is fitted on a grid of steps of at most sqrt(2), and its exact held-out
ratio is also given above the edge it was sized above (where it acts), beside the pooled one."""

from types import SimpleNamespace

import numpy as np

from piezoctl.diagnose import misfit, select
from piezoctl.dsp import filt, mode_filter
from piezoctl.ident.terms import TERMS

DT = 1e-4
F = 1000.0   # the concealed mode [Hz]
R = 0.08     # its residue


def _best_left(h, e, grid):
    """The least share of ``e`` the term's columns at F leave over the dampings in ``grid``."""
    term = TERMS["unmodeled_resonance"]
    out = []
    for z in grid:
        X = term.basis(h, F, z, DT)
        c = np.linalg.lstsq(X, e, rcond=None)[0]
        out.append(float(np.sqrt(np.sum((e - X @ c) ** 2) / np.sum(e ** 2))))
    return min(out)


def test_the_damping_grid_keeps_the_range_in_steps_of_at_most_sqrt2():
    term = TERMS["unmodeled_resonance"]
    g = np.asarray(term.SETTING_DAMPINGS)
    assert g[0] == min(term.DAMPINGS) and g[-1] == max(term.DAMPINGS)
    assert np.all(g[1:] / g[:-1] <= np.sqrt(2.0) + 1e-9)
    st = term.settings(SimpleNamespace(mode_freqs=[F]))
    assert {z for _, z in st} == set(term.SETTING_DAMPINGS)


def test_a_ring_between_the_old_grid_points_is_fitted():
    """Steps ring the mode; at every damping of the range (a dense scan) the grid's best leaves at most a tenth of
    the branch (a sixth of the envelope one decay time on), where the vocabulary's steps of 2 to 2.5 left more."""
    rng = np.random.default_rng(1)
    h = np.repeat(rng.uniform(-5, 5, 40), 1000)
    term = TERMS["unmodeled_resonance"]
    worst_new, worst_old = 0.0, 0.0
    for z in np.geomspace(0.005, 0.05, 25):
        e = R * (filt(*mode_filter(F, z, DT), h) - h)
        worst_new = max(worst_new, _best_left(h, e, term.SETTING_DAMPINGS))
        worst_old = max(worst_old, _best_left(h, e, term.DAMPINGS))
    assert worst_new < 0.1
    assert worst_old > 1.5 * worst_new


def test_above_per_recording_filters_each_recording_alone():
    """A step between two recordings is no edge of either: filtered per recording, a constant level per recording
    leaves nothing above the edge; a recording too short to filter is left out."""
    rec = np.repeat([0, 1, 2], [4000, 4000, 40])
    e = np.where(rec == 0, 1.0, -2.0)
    h, done = misfit.above_per_recording(e, rec, DT, 800.0)
    assert np.all(done[rec < 2]) and not np.any(done[rec == 2])
    assert np.max(np.abs(h[rec < 2])) < 1e-6
    t = np.arange(rec.size) * DT
    ring = 0.1 * np.sin(2 * np.pi * 1500.0 * t)
    h, _ = misfit.above_per_recording(e + ring, rec, DT, 800.0)
    core = (rec == 0) & (np.arange(rec.size) > 500) & (np.arange(rec.size) < 3500)
    assert np.allclose(h[core], ring[core], atol=0.01)


def test_the_exact_check_is_given_above_the_edge_where_the_term_acts():
    """A large slow misfit the term cannot touch and a 1.5 kHz ring it takes: the pooled exact ratio stays near 1,
    the ratio above the edge is the ring's."""
    rng = np.random.default_rng(4)
    n = 20_000
    t = np.arange(n) * DT
    slow = np.sin(2 * np.pi * 3.0 * t)
    ring = 0.1 * np.sin(2 * np.pi * 1500.0 * t) * np.exp(-((t % 0.25) / 0.03))
    noise = 0.002 * rng.standard_normal(n)
    e_old, e_new = slow + ring + noise, slow + 0.2 * ring + noise
    fold_all = ((np.arange(n) * 8) // n) % 2
    rec = np.zeros(n, int)
    ex = []
    for f in (0, 1):
        test = fold_all == 1 - f
        hb, done = misfit.above_per_recording(e_old, rec, DT, 1000.0)
        ha, _ = misfit.above_per_recording(e_new, rec, DT, 1000.0)
        m = done & test
        ex.append({"sse_before": float(np.sum(e_old[test] ** 2)), "sse_after": float(np.sum(e_new[test] ** 2)),
                   "n": int(np.sum(test)), "above": {"above_hz": 1000.0, "sse_before": float(np.sum(hb[m] ** 2)),
                                                     "sse_after": float(np.sum(ha[m] ** 2)), "n": int(np.sum(m))}})
    a = select._exact_above(ex, 2.0)
    pooled = np.sqrt(sum(x["sse_after"] for x in ex) / sum(x["sse_before"] for x in ex))
    assert pooled > 0.95
    assert a["above_hz"] == 1000.0
    assert all(0.15 < r < 0.3 for r in a["fold_ratios"])
    assert 0.15 < a["nrmse_after"] / a["nrmse_before"] < 0.3
    assert select._exact_above([{k: v for k, v in x.items() if k != "above"} for x in ex], 2.0) is None
