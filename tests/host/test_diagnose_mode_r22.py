"""Round 22, the concealed mode: its exact check is read above the edge it is sized above as well as on the whole
band. A mode whose exact refined model lowers the whole band's held-out error but raises the error above its edge
is refused (what it takes lies below the edge); the next significant candidate is then checked."""

import types

from piezoctl.diagnose import select
from piezoctl.ident.terms import TERMS

EDGE = 1386.0


def _fold(before, after, above_before=None, above_after=None):
    x = {"sse_before": before, "sse_after": after, "n": 1000, "per_recording": [(before, after)]}
    if above_before is not None:
        x["above"] = {"above_hz": EDGE, "sse_before": above_before, "sse_after": above_after, "n": 400}
    return x


def _cand(name, exact):
    return select.Candidate(term=TERMS[name], ratio=0.5, fold_ratios=[0.5, 0.5], nrmse_before=1e-3,
                            nrmse_after=5e-4, t=5.0, p=1e-5, n_active=10, p_max=1e-3, dbic=-30.0, n_eff=100.0,
                            significant=True, setting=[(1960.0, 0.05), (1960.0, 0.05)], coef=[[0.0], [0.0]],
                            exact=exact)


def _first(evals):
    fctx = [types.SimpleNamespace(names=["rev0"])] * 2
    return select._first_exact(evals, fctx, None, None, 1.0, lambda *_: None)


def test_a_mode_that_raises_the_error_above_its_edge_is_refused_and_the_next_candidate_checked():
    """The whole band's error falls to 0.3 of itself (the mode's static share standing in for the base's gain)
    while above the edge it rises 1.6 times: vetoed, with both figures; the second candidate is returned."""
    mode = _cand("unmodeled_resonance", [_fold(1.0, 0.09, 0.01, 0.026), _fold(1.0, 0.09, 0.01, 0.026)])
    other = _cand("amplifier_slew_limit", [_fold(1.0, 0.5), _fold(1.0, 0.5)])
    got = _first([mode, other])
    assert got is other
    assert mode.veto is not None and "not above 1386 Hz" in mode.veto
    assert max(mode.exact_fold_ratios) < 0.31
    assert min(mode.exact_above["fold_ratios"]) > 1.5


def test_a_mode_that_lowers_the_error_above_its_edge_passes():
    """Above the edge 0.5 of the error's RMS in each fold, the whole band 0.9: the mode is returned."""
    mode = _cand("unmodeled_resonance", [_fold(1.0, 0.81, 0.04, 0.01), _fold(1.0, 0.81, 0.04, 0.01)])
    assert _first([mode]) is mode and mode.veto is None
    assert max(mode.exact_above["fold_ratios"]) < 0.51


def test_one_fold_above_the_edge_not_lowered_is_enough_to_refuse():
    """The whole-band rule asks each fold; so does the rule above the edge."""
    mode = _cand("unmodeled_resonance", [_fold(1.0, 0.5, 0.04, 0.01), _fold(1.0, 0.5, 0.04, 0.041)])
    assert _first([mode]) is None and mode.veto is not None
