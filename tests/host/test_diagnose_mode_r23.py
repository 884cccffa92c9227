"""Round 23, the concealed mode: the block test reads where the mode is sized (above its edge) as well as on the whole
band, the smaller p counting twice (two looks at one test); BIC passes in either view under the first round's size
gate, and stays the whole band's once the size gate is loosened after a first term."""

import numpy as np

from piezoctl.diagnose import select, significance as sg
from piezoctl.ident.terms import TERMS

DT = 1e-4
F = 1200.0   # the mode [Hz]
EDGE = F / np.sqrt(2.0)
P_MAX = sg.ALPHA / 12


def _within(x):
    return x <= sg.RATIO_MAX


def _whole(p_above, dbic_above):
    return {"above_hz": EDGE, "fold_ratios": [0.97, 0.98], "credited_ratio": 0.97, "p_above": p_above,
            "dbic_above": dbic_above, "share_above": 0.8}


def test_a_ring_beside_a_slow_misfit_passes_above_its_edge_where_the_whole_band_refuses():
    """Steps ring the mode beside a slow misfit 30 times the ring that the term does not touch: on the whole band
    the block test does not find the ring, above the edge it does, at less than half the level (two looks)."""
    rng = np.random.default_rng(3)
    n = 120_000
    t = np.arange(n) * DT
    h = np.repeat(rng.uniform(-5, 5, n // 2500), 2500)
    ring = 0.05 * TERMS["unmodeled_resonance"].basis(h, F, 0.02, DT)[:, 0]
    slow = 30 * np.std(ring) * np.sin(2 * np.pi * 0.7 * t + 1.0) * (1 + 0.5 * np.sin(0.3 * t))
    e_before = slow + ring + 0.002 * rng.standard_normal(n)
    corr = 0.9 * ring
    blocks, rec = (np.arange(n) * DT // 1.0).astype(int), np.zeros(n, int)
    ev = select._above_edge_evidence(e_before, corr, blocks, rec, DT, EDGE, 6)
    assert ev["p_above"] < P_MAX / 2 and ev["dbic_above"] < 0
    units = sg.test_units(e_before, blocks, rec, DT, corr)
    _, p_whole, _ = sg.active_block_test(e_before, e_before - corr, corr, blocks, units)
    assert p_whole > P_MAX
    whole = {"above_hz": EDGE, "fold_ratios": [0.99, 0.99], "credited_ratio": 0.99, **ev}
    assert select._linearized_gates([0.5, 0.5], p_whole, -10.0, whole, P_MAX, _within)
    assert whole["whole_band_gates"] is False   # the whole band's block test alone refuses it
    assert whole["p_gate"] == 2 * ev["p_above"]


def test_two_looks_count_twice():
    """The smaller of the two p counts twice: above the edge just under the level is not enough, under half is."""
    assert not select._linearized_gates([0.7, 0.7], 0.5, -10.0, _whole(0.9 * P_MAX, -10.0), P_MAX, _within)
    assert select._linearized_gates([0.7, 0.7], 0.5, -10.0, _whole(0.4 * P_MAX, -10.0), P_MAX, _within)
    # the whole band's p alone, as small, passes too; just under the level it no longer does (it counts twice)
    assert select._linearized_gates([0.7, 0.7], 0.4 * P_MAX, -10.0, _whole(0.5, -10.0), P_MAX, _within)
    assert not select._linearized_gates([0.7, 0.7], 0.9 * P_MAX, -10.0, _whole(0.5, -10.0), P_MAX, _within)


def test_bic_in_either_view_under_the_first_size_gate_only():
    """Under the first round's size gate (0.8 above the edge) BIC passes in either view; after the first term the
    size gate is 1.0 and the whole band's BIC is the size guard left: the view above the edge does not count."""
    assert select._linearized_gates([0.7, 0.7], 1e-6, +8.0, _whole(1e-6, -50.0), P_MAX, _within, True)
    assert select._linearized_gates([0.7, 0.7], 1e-6, -8.0, _whole(1e-6, +50.0), P_MAX, _within, True)
    assert not select._linearized_gates([0.7, 0.7], 1e-6, +8.0, _whole(1e-6, +5.0), P_MAX, _within, True)
    further = lambda x: x < 1.0   # noqa: E731 (the size gate after the first term)
    assert not select._linearized_gates([0.9, 0.9], 1e-6, +8.0, _whole(1e-6, -50.0), P_MAX, further, False)
    assert select._linearized_gates([0.9, 0.9], 1e-6, -8.0, _whole(1e-6, -50.0), P_MAX, further, False)
    assert not select._linearized_gates([0.85, 0.7], 1e-9, -1e4, _whole(1e-9, -1e4), P_MAX, _within, True)


def test_a_term_without_an_edge_keeps_the_whole_band_gates():
    """Only a term sized above an edge has a second view; the others' gates are the whole band's, unchanged."""
    assert not select._linearized_gates([0.7, 0.7], 1.05 * P_MAX, -10.0, None, P_MAX, _within)
    assert select._linearized_gates([0.7, 0.7], 0.9 * P_MAX, -10.0, None, P_MAX, _within)
    assert not select._linearized_gates([0.7, 0.7], 1e-9, +1.0, None, P_MAX, _within)
    drift_like = {"beyond_calibrated_range": True, "fold_ratios": [0.9, 0.9], "credited_ratio": 0.9}
    assert select._linearized_gates([0.7, 0.7], 0.9 * P_MAX, -10.0, drift_like, P_MAX, _within)
    assert "p_gate" not in drift_like
