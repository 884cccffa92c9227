"""Round 24 (issue 12 item 6, docs/diagnose-rounds/round-24.md "Round 24: speed"): the bounded fits of a term's
settings skip BVLS's iterations when the unbounded solution's error is already above the best setting's.

- ``solve.lstsq_box_below`` returns ``lstsq_box``'s floats bit for bit whenever it returns a fit (unbounded
  solution feasible or not, box and lower bounds, a rank-deficient design), and returns None only when the
  bounded fit's error is above the bound it was given.
- ``select.best_setting`` chooses the same setting with the same coefficients, training error and prediction
  as a search that fits every setting in full.
"""

import numpy as np
import pytest

from piezoctl.diagnose import select as S
from piezoctl.diagnose.solve import SSE_MARGIN, lstsq_box, lstsq_box_below


def _problem(seed, n=20_000, k=6, infeasible=True):
    """A tall design of columns of different scales, a response, and lower bounds that the unbounded solution
    violates (``infeasible``) or meets."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, k)) * 10.0 ** rng.uniform(-3, 3, k)
    th = rng.normal(size=k) / np.sqrt(np.mean(X ** 2, axis=0))
    y = X @ th + 0.3 * np.std(X @ th) * rng.normal(size=n)
    lo = np.full(k, -np.inf)
    hi = np.full(k, np.inf)
    j = int(np.argmin(th)) if infeasible else int(np.argmax(th))
    lo[j] = 0.0   # th[j] < 0 (infeasible) or > 0 with the noise small (feasible)
    if infeasible:
        hi[(j + 1) % k] = th[(j + 1) % k] - abs(th[(j + 1) % k])   # an upper bound the solution violates too
    return X, y, lo, hi


def _sse(X, y, th):
    r = y - X @ th
    return float(r @ r)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("infeasible", [True, False])
def test_same_floats_when_not_skipped(seed, infeasible):
    X, y, lo, hi = _problem(seed, infeasible=infeasible)
    ref = lstsq_box(X, y, lo, hi)
    got = lstsq_box_below(X, y, lo, hi, np.inf)
    assert got is not None
    assert np.array_equal(got.view(np.int64), ref.view(np.int64))
    # a scalar upper bound, as the lower-bounded fits pass it
    ref2 = lstsq_box(X, y, lo, np.inf)
    got2 = lstsq_box_below(X, y, lo, np.inf, np.inf)
    assert np.array_equal(got2.view(np.int64), ref2.view(np.int64))


def test_rank_deficient_design_same_floats():
    X, y, lo, hi = _problem(7)
    X = np.column_stack([X, X[:, 0] * 2.0, np.zeros(X.shape[0])])   # a repeated and a zero column
    lo, hi = np.append(lo, [0.0, -np.inf]), np.append(hi, [np.inf, np.inf])
    ref = lstsq_box(X, y, lo, hi)
    got = lstsq_box_below(X, y, lo, hi, np.inf)
    assert np.array_equal(got.view(np.int64), ref.view(np.int64))


@pytest.mark.parametrize("seed", range(6))
def test_skipped_only_above_the_bound(seed):
    """None exactly when the bound lies below the unbounded minimum; the bounded error is then above it."""
    X, y, lo, hi = _problem(seed)
    full = lstsq_box(X, y, lo, hi)
    s_box = _sse(X, y, full)
    s_free = _sse(X, y, np.linalg.lstsq(X, y, rcond=None)[0])
    assert s_free < s_box   # the bounds act
    below = s_free * (1.0 - 1e-3)
    assert lstsq_box_below(X, y, lo, hi, below) is None
    assert s_box > below
    between = 0.5 * (s_free + s_box)   # above the unbounded minimum: the fit is made, the same floats
    got = lstsq_box_below(X, y, lo, hi, between)
    assert got is not None and np.array_equal(got.view(np.int64), full.view(np.int64))


def test_feasible_never_skipped():
    """An unbounded solution within the bounds is the answer, whatever the bound."""
    X, y, lo, hi = _problem(3, infeasible=False)
    ref = lstsq_box(X, y, lo, hi)
    got = lstsq_box_below(X, y, lo, hi, 0.0)
    assert got is not None and np.array_equal(got.view(np.int64), ref.view(np.int64))


class _Ctx:
    def __init__(self, cols):
        self.valid = [np.ones(cols[0].shape[0], bool)]
        self.signals = [None]
        self.design_cache = {}
        self.cols = cols


class _Term:
    """Settings 0..n-1, each a design of a shared column and one of its own; the own column's gain >= 0."""
    name = "test term"

    def __init__(self, n):
        self.n = n

    def settings(self, ctx):
        return list(range(self.n))

    def refine(self, ctx, st, level):
        return []

    def lower(self, ctx):
        return [-np.inf, 0.0]

    def regressors(self, ctx, s, st):
        return np.column_stack([ctx.cols[0], ctx.cols[st + 1]])


def _full_search(ctx, term, e, train, test, rows, nuis):
    """best_setting's choice with every setting fitted in full (round 23's search)."""
    best = None
    for st in term.settings(ctx):
        d = S._design(ctx, term, st)
        th, _, sse = S._fit_predict(d.X, e, train, test, rows, term.lower(ctx), nuis, predict=False)
        if best is None or sse < best[2]:
            best = (st, d, sse, th)
    return best


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("nested", [False, True])
def test_best_setting_unchanged(seed, nested, monkeypatch):
    rng = np.random.default_rng(100 + seed)
    n, n_set = 30_000, 8
    t = np.arange(n) / 1e4
    cols = [np.sin(2 * np.pi * 0.3 * t)] + [np.sin(2 * np.pi * (0.5 + 0.2 * j) * t + j) for j in range(n_set)]
    # the response: the shared column, settings 2 and 5 with opposite signs (5 infeasible), noise
    e = 0.7 * cols[0] + 0.5 * cols[3] - 0.4 * cols[6] + 0.05 * rng.normal(size=n)
    ctx, term = _Ctx(cols), _Term(n_set)
    fold = (np.arange(n) // 1000) % 2
    train, test = fold == 0, fold == 1
    nuis = None
    if nested:   # a nuisance with box bounds (an initial state's gains), as the initial-state terms have
        Nc = np.column_stack([np.cos(2 * np.pi * 0.1 * t), (t > t[-1] / 2).astype(float)])
        idx = S.train_rows(train, 20_000)
        nuis = (Nc[idx], Nc[test], (np.array([-np.inf, -1.0]), np.array([np.inf, 1.0])))
    calls = {"skipped": 0}
    real = S.lstsq_box_below

    def counting(*a):
        th = real(*a)
        calls["skipped"] += th is None
        return th
    monkeypatch.setattr(S, "lstsq_box_below", counting)
    st, d, sse, pa, th = S.best_setting(ctx, term, e, train, test, 20_000, nuis)
    ref = _full_search(ctx, term, e, train, test, 20_000, nuis)
    assert st == ref[0] == 2
    assert sse == ref[2]
    th_ref = ref[3] if nuis is None else ref[3][nuis[0].shape[1]:]
    assert np.array_equal(np.asarray(th), np.asarray(th_ref))
    assert np.array_equal(pa, S._predict(ref[1].X, ref[3], test, nuis))
    assert calls["skipped"] >= 1   # the settings of the wrong sign were not iterated


def test_margin_is_small_and_positive():
    assert 0.0 < SSE_MARGIN <= 1e-4
