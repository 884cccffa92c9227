"""Round 23 (docs/diagnose-rounds/round-23.md, "Round 23: speed and memory"): the rate term's widened plays are
kept for a recurring operator, drive and width (``plane_width_change_cached``). It changes no float."""

import copy

import numpy as np

from piezoctl.ident import terms as T
from piezoctl.ident.terms import TERMS
from piezoctl.models import hysteresis as hy
from test_diagnose_speed_round20 import _rate_evaluation, _two_contexts


def _bits(a):
    return np.ascontiguousarray(a).view(np.int64)


def _plane_and_drive():
    ctx, _ = _two_contexts()
    hp = ctx.base["hysteresis"]
    assert hp.get("type") == "plane" and any(float(r) > 0 for r in hp["r"])
    s = ctx.signals[0]
    w = TERMS["rate_dependent_hysteresis"].width(s.v, s.dt, 10.0, 0.8)
    return hp, np.asarray(s.v, float), w


def test_the_cached_width_change_is_the_same_floats_and_recurs_only_for_the_same_operator_drive_and_width():
    hy.clear_output_cache()
    hp, v, w = _plane_and_drive()
    plain = hy.plane_width_change(hp, v, w)
    assert np.any(plain != 0.0)
    first = hy.plane_width_change_cached(hp, v, w)
    assert np.array_equal(_bits(first), _bits(plain)) and not first.flags.writeable
    assert hy.plane_width_change_cached(hp, v.copy(), w.copy()) is first      # equal arrays: the kept result
    moved = dict(hp, offset=float(hp.get("offset", 0.0)) + 1.0)               # not read by the change
    assert hy.plane_width_change_cached(moved, v, w) is first
    v1 = v.copy()
    v1[v.size // 2] = np.nextafter(v1[v.size // 2], np.inf)                   # one ulp of one sample
    w1 = w.copy()
    w1[v.size // 3] = np.nextafter(w1[v.size // 3], np.inf)
    hp1 = copy.deepcopy(hp)
    j = next(i for i, r in enumerate(hp["r"]) if float(r) > 0)
    hp1["values"][j] = list(np.asarray(hp1["values"][j], float) * 1.001)     # another operator
    for args in ((hp, v1, w), (hp, v, w1), (hp1, v, w)):
        got = hy.plane_width_change_cached(*args)
        assert got is not first
        assert np.array_equal(_bits(got), _bits(hy.plane_width_change(*args)))
    assert not np.array_equal(hy.plane_width_change_cached(hp1, v, w), plain)
    hy.clear_output_cache()
    assert hy.plane_width_change_cached(hp, v, w) is not first                # emptied with the output cache
    hy.clear_output_cache()


def test_the_width_cache_keeps_its_bound(monkeypatch):
    hy.clear_output_cache()
    hp, v, w = _plane_and_drive()
    monkeypatch.setattr(hy, "_WIDTH_CACHE_MAX_SAMPLES", v.size + 1)
    a = hy.plane_width_change_cached(hp, v, w)
    assert hy.plane_width_change_cached(hp, v, w) is a                        # one fits
    b = hy.plane_width_change_cached(hp, v, w * 1.5)                          # a second does not: computed, not kept
    assert hy.plane_width_change_cached(hp, v, w * 1.5) is not b
    assert sum(x.size for x in hy._WIDTH_CACHE.values()) <= v.size + 1
    assert np.array_equal(_bits(b), _bits(hy.plane_width_change(hp, v, w * 1.5)))
    hy.clear_output_cache()


def test_the_rate_candidate_is_the_same_with_the_width_cache_and_without(monkeypatch):
    hy.clear_output_cache()
    _, _, run = _rate_evaluation()
    cached = run()
    assert len(hy._WIDTH_CACHE) > 0
    hy.clear_output_cache()
    monkeypatch.setattr(T, "plane_width_change_cached", hy.plane_width_change)   # every change computed
    _, _, run = _rate_evaluation()
    plain = run()
    assert len(hy._WIDTH_CACHE) == 0
    assert cached.setting == plain.setting and cached.fold_ratios == plain.fold_ratios
    assert cached.p == plain.p and cached.ratio == plain.ratio and cached.credited == plain.credited
    assert all(np.array_equal(_bits(a), _bits(b)) for a, b in zip(cached.coef, plain.coef))
    assert cached.significant == plain.significant and cached.veto == plain.veto
    hy.clear_output_cache()


# ---- base_lag from the blocks' QR factors (select._block_factors) against round 22's stacked columns ----

import types  # noqa: E402

import scipy.signal as sps  # noqa: E402

from piezoctl.diagnose import select as S  # noqa: E402


def _base_lag_round22(ctx, e, block_all):
    """Round 22's base_lag (copied): the stacked columns X_lag, their SVDs."""
    ids = np.unique(block_all)
    D = S.dynamics_nuisance(ctx)
    X_lag = np.hstack([D[:, 1:2], np.column_stack([D[:, 0] * (block_all == b) for b in ids])])
    c, var = S._block_lags(X_lag, ids, e, S.hysteresis_nuisance(ctx))
    ok = var > 0
    if ok.sum() < 2:
        return None
    w = 1.0 / var[ok]
    P = np.linalg.pinv(X_lag)
    best, lag = np.inf, 0
    for d in S.LAG_SPREAD_DELAYS:
        z = np.concatenate([np.concatenate([np.full(d, s.ydyn[0]), np.asarray(s.ydyn, float)[:s.ydyn.size - d]])[v]
                            - np.asarray(s.ydyn, float)[v] for s, v in zip(ctx.signals, ctx.valid)])
        k = (P @ z)[-ids.size:]
        r = float(np.sum(w * (c[ok] - k[ok]) ** 2) / np.sum(w))
        if r < best:
            best, lag = r, int(d)
    return float(lag), float(np.sqrt(best))


def _lag_case(seed, n=24_000, m=5, labels="sorted", zero_block=False):
    """A model output low-passed at 20 to 400 Hz block by block, a residual of a lag that differs per block plus
    hysteresis-like nuisance columns and noise; block labels sorted, shuffled or with a block where the first
    derivative is zero (no lag there: its variance is 0 and it is left out)."""
    rng = np.random.default_rng(seed)
    nb = 12
    blocks = np.repeat(np.arange(nb), n // nb)
    x = np.empty(n)
    for b, fc in enumerate(np.geomspace(20.0, 400.0, nb)):
        bb, aa = sps.butter(2, fc, fs=1e4)
        x[blocks == b] = 3.0 * sps.lfilter(bb, aa, rng.standard_normal(n))[blocks == b]
    if zero_block:
        x[blocks == 5] = x[np.flatnonzero(blocks == 5)[0]]
    Nh = np.column_stack([np.tanh(x * (j + 1) / 3.0) for j in range(m)])
    lags = rng.integers(1, 9, nb)
    e = np.empty(n)
    for b, d in enumerate(lags):
        xd = np.concatenate([np.full(d, x[0]), x[:-d]])
        e[blocks == b] = (xd - x)[blocks == b]
    e += Nh @ rng.normal(0, 0.1, m) + 0.05 * np.std(e) * rng.standard_normal(n)
    if labels == "shuffled":   # labels not in time order, not contiguous integers
        blocks = rng.permutation(np.arange(100, 100 + 3 * nb, 3))[blocks]
    dx = np.gradient(x) / 1e-4
    ctx = types.SimpleNamespace(nuisance=Nh, dyn_nuisance=np.column_stack([dx, np.gradient(dx) / 1e-4]), n_rec=1,
                                bound_lag=False, signals=[types.SimpleNamespace(ydyn=x)], valid=[np.ones(n, bool)])
    return ctx, e, blocks


def test_base_lag_from_block_factors_equals_round_22s_to_rounding():
    for seed, labels, zero in ((1, "sorted", False), (2, "shuffled", False), (3, "sorted", True),
                               (4, "shuffled", True)):
        ctx, e, blocks = _lag_case(seed, labels=labels, zero_block=zero)
        old = _base_lag_round22(ctx, e, blocks)
        new = S.base_lag(ctx, e, blocks)
        assert old is not None and new is not None
        assert new[0] == old[0], (seed, old, new)                         # the same pure delay
        assert abs(new[1] - old[1]) <= 1e-9 * abs(old[1]), (seed, old, new)   # its departure to rounding


def test_block_factors_give_the_stacked_columns_gram_and_fits():
    ctx, e, blocks = _lag_case(5, n=6000, labels="shuffled")
    ids, inv = np.unique(blocks, return_inverse=True)
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(ids.size + 1))
    D = S.dynamics_nuisance(ctx)
    C = np.hstack([ctx.nuisance, D[:, 1:2]])
    X = np.hstack([C, np.column_stack([D[:, 0] * (blocks == b) for b in ids])])
    Sf, (Qe,), _ = S._block_factors(C, D[:, 0], order, bounds, (e,))
    assert np.allclose(Sf.T @ Sf, X.T @ X, rtol=1e-12, atol=1e-12 * np.abs(X.T @ X).max())
    th_x = np.linalg.lstsq(X, e, rcond=None)[0]
    th_s = np.linalg.lstsq(Sf, Qe, rcond=np.finfo(float).eps * max(X.shape))[0]
    assert np.allclose(th_s, th_x, rtol=1e-9, atol=1e-9 * np.abs(th_x).max())
    assert not np.allclose(th_s[-ids.size:], th_s[-ids.size:].mean())    # the blocks' lags differ: a real test
