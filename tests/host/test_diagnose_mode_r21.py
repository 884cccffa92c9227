"""Round 21, the concealed mode: named only where a recording excites it (most of its held-out correction lies above
the edge it is sized above, where a mode rings); the block test above that edge is recorded beside the whole band's."""

import numpy as np

from piezoctl.diagnose import select, significance as sg
from piezoctl.dsp import filt, mode_filter
from piezoctl.ident.terms import TERMS

DT = 1e-4
F = 1200.0   # the mode [Hz]
EDGE = F / np.sqrt(2.0)


def _column(h, z=0.02):
    return TERMS["unmodeled_resonance"].basis(h, F, z, DT)[:, 0]


def _blocks(n, per_s=1.0):
    return (np.arange(n) * DT // per_s).astype(int)


def test_a_ring_after_steps_is_mostly_above_the_edge_and_the_block_test_there_finds_it():
    """Steps ring the mode: the branch's correction lies above the edge, and beside a slow misfit 30 times the
    ring that the term does not touch, the block test above the edge finds the ring (p below the round's level)
    where the whole band's does not."""
    rng = np.random.default_rng(2)
    n = 120_000
    t = np.arange(n) * DT
    h = np.repeat(rng.uniform(-5, 5, n // 2500), 2500)
    ring = 0.05 * _column(h)
    slow = 30 * np.std(ring) * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6, 1)) * (1 + 0.5 * np.sin(0.3 * t))
    noise = 0.002 * rng.standard_normal(n)
    e_before = slow + ring + noise
    corr = 0.9 * ring + 0.1 * slow * 0.01 * rng.standard_normal(n)   # the term's held-out prediction, not exact
    blocks, rec = _blocks(n), np.zeros(n, int)
    ev = select._above_edge_evidence(e_before, corr, blocks, rec, DT, EDGE)
    assert ev["share_above"] > 0.8
    assert ev["p_above"] < 1e-4
    assert TERMS["unmodeled_resonance"].acts_below_edge(ev["share_above"], EDGE) is None
    units = sg.test_units(e_before, blocks, rec, DT, corr)
    _, p_whole, _ = sg.active_block_test(e_before, e_before - corr, corr, blocks, units)
    assert p_whole > 10 * ev["p_above"]


def test_a_mode_no_recording_excites_is_refused():
    """Smooth sines far below the mode (the slow designs' reveal: at most a quarter of the stage's first mode) do
    not ring it; fitted to a mass-line misfit of the base (the second derivative of the response, what a stage's
    own mode left out of an order-0 base leaves), the branch's correction lies below its edge and is refused."""
    n = 60_000
    t = np.arange(n) * DT
    h = sum(a * np.sin(2 * np.pi * f * t) for a, f in ((20.0, 23.0), (10.0, 41.0), (5.0, 67.0)))
    w = 2 * np.pi * 867.0
    mass = -np.gradient(np.gradient(h, DT), DT) / w ** 2   # the missing mode's quasi-static part
    x = _column(h)
    c = float(np.dot(x, mass) / np.dot(x, x))
    ev = select._above_edge_evidence(mass, c * x, _blocks(n), np.zeros(n, int), DT, EDGE)
    assert ev["share_above"] < 0.1
    why = TERMS["unmodeled_resonance"].acts_below_edge(ev["share_above"], EDGE)
    assert why is not None and "no recording excites" in why


def test_only_the_mode_sets_a_share_and_its_threshold_is_half():
    term = TERMS["unmodeled_resonance"]
    assert term.acts_below_edge(0.51, EDGE) is None and term.acts_below_edge(0.49, EDGE) is not None
    assert all(TERMS[k].acts_below_edge(0.0, EDGE) is None for k in TERMS if k != "unmodeled_resonance")


def test_the_columns_of_a_ring_and_of_a_mass_line_differ_in_where_their_energy_lies():
    """The physics the threshold reads: the branch ``M(w) - w`` at a step is a ring at the mode (above the edge),
    at a smooth sine a quarter of the mode and below it is ``-(f'/f)^2 w`` (below the edge)."""
    from piezoctl.diagnose.misfit import above_per_recording
    n = 40_000
    t = np.arange(n) * DT
    rec = np.zeros(n, int)
    for h, lo, hi in ((np.where(t % 0.5 < 0.25, 1.0, -1.0), 0.8, 1.0),
                      (np.sin(2 * np.pi * F / 4 * t), 0.0, 0.05)):
        x = filt(*mode_filter(F, 0.02, DT), h) - h
        above, _ = above_per_recording(x, rec, DT, EDGE)
        share = float(np.sum(above[2000:-2000] ** 2) / np.sum(x[2000:-2000] ** 2))
        assert lo <= share <= hi

