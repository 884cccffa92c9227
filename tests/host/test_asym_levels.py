"""Round 26: the asymmetric knee is tested beyond a level per recording (ident.terms.AsymmetricHysteresis.
test_nuisance): a recording starts in a hysteresis state its unknown history left, and the base errs there by a level
of its own that the knee, without a constant, cannot take."""

import types

import numpy as np

from piezoctl.diagnose.select import _fit_predict, _nuisance_parts
from piezoctl.ident.terms import AsymmetricHysteresis, TERMS


def _ctx(lengths, settled_from=0):
    """A context stub: recordings of the given lengths, the first ``settled_from`` samples of each unsettled."""
    sig = [types.SimpleNamespace(index=i, u=np.zeros(n)) for i, n in enumerate(lengths)]
    valid = [np.arange(n) >= settled_from for n in lengths]
    return types.SimpleNamespace(signals=sig, valid=valid, n_rec=len(lengths), refit_cache={}, accepted_flex=None)


def test_one_level_column_per_recording_on_its_settled_rows():
    ctx = _ctx([30, 50, 20], settled_from=5)
    N = AsymmetricHysteresis().test_nuisance(ctx)
    assert N.shape == (25 + 45 + 15, 3)
    assert np.all(N.sum(axis=1) == 1.0)                     # each row belongs to exactly one recording
    assert list(N.sum(axis=0)) == [25.0, 45.0, 15.0]        # its own settled rows, in the stacking order
    assert np.all(N[:25, 0] == 1.0) and np.all(N[25:70, 1] == 1.0) and np.all(N[70:, 2] == 1.0)
    assert AsymmetricHysteresis().test_nuisance(ctx) is N   # cached on the context


def test_the_levels_are_the_knees_own_test_nuisance_only():
    ctx = _ctx([10, 10])
    term = TERMS["asymmetric_hysteresis"]
    term_nested, AsymmetricHysteresis.nested = AsymmetricHysteresis.nested, False   # no base in the stub
    try:
        parts = _nuisance_parts(ctx, term)
        assert len(parts) == 1 and parts[0].shape == (20, 2)
        assert _nuisance_parts(ctx, term, own_test=False) == []
    finally:
        AsymmetricHysteresis.nested = term_nested


def test_beyond_the_levels_the_knee_gets_its_own_size():
    # two recordings crossing a knee: the base errs by -1.5 and -4.6 um (their levels) and misses an extra
    # 0.5 x^2 beyond the knee on both; fitted on alternate blocks without the levels the knee's gain takes the
    # levels' share where x is large, with them it is the extra's
    rng = np.random.default_rng(3)
    n = 4000
    t = np.arange(n)
    x = np.concatenate([np.maximum(np.sin(2 * np.pi * t / 800), 0.0)] * 2)
    level = np.concatenate([np.full(n, -1.5), np.full(n, -4.6)])
    e = level + 0.5 * x ** 2 + 0.02 * rng.standard_normal(2 * n)
    X = (x ** 2)[:, None]
    train = (np.arange(2 * n) // 200) % 2 == 0
    test = ~train
    rows = 10 ** 9   # every training row
    N = AsymmetricHysteresis().test_nuisance(_ctx([n, n]))
    th_alone, *_ = _fit_predict(X, e, train, test, rows)
    th_nested, *_ = _fit_predict(X, e, train, test, rows, nuis=(N[train], N[test], None))
    assert abs(th_nested[-1] - 0.5) < 0.02
    assert abs(th_alone[-1] - 0.5) > 1.0
