"""Round 27: creep's step-response test fits only the time constants the dwells can size (slow_signature.py,
``step_response_test`` with ``dwell_taus``), as creep's model on the dwells does (round 19)."""

import numpy as np

from piezoctl.diagnose.slow_signature import ALPHA_SIGNATURE, dwell_taus, step_response_test
from piezoctl.dsp import filt
from piezoctl.ident.terms import TERMS
from test_diagnose_slow import _creep, _ctx, _measured
from test_slow_signature_steps import LP, _with_dynamics

ROWS = 200000


def _step_test(ctx, effect, seed):
    e, fold, block = _measured(ctx, effect, np.random.default_rng(seed))
    return step_response_test([ctx, ctx], [e, e], fold, block, ROWS)


def test_the_step_test_fits_only_the_time_constants_the_dwells_can_size():
    """Dwells under 2 s: the 3 s and 10 s elements (a line over each dwell, which the slope per recording and the
    level per dwell share) get no column; the test still finds the tail of a log-law creep."""
    ctx = _with_dynamics(_ctx(np.random.default_rng(1)))
    taus = TERMS["creep"].taus(ctx)
    assert taus == [0.1, 0.3, 1.0, 3.0, 10.0]
    r = _step_test(ctx, lambda s: filt(*LP, _creep(s)), 3)
    assert r is not None
    assert r["taus_s"] == dwell_taus(ctx, taus) == [0.1, 0.3, 1.0]
    assert all(len(g) == 3 for g in r["gains"])
    assert r["p"] < ALPHA_SIGNATURE and max(r["fold_ratios"]) < 0.5, r


def test_no_time_constant_the_dwells_can_size_no_test(monkeypatch):
    """When every time constant is longer than the longest dwell the dwells size none: no test (None), as no
    dwell at all gives none."""
    ctx = _with_dynamics(_ctx(np.random.default_rng(1)))
    monkeypatch.setattr(type(TERMS["creep"]), "taus", lambda self, c: [3.0, 10.0])
    assert dwell_taus(ctx, TERMS["creep"].taus(ctx)) == []
    assert _step_test(ctx, lambda s: filt(*LP, _creep(s)), 3) is None
