"""The diagnosis' faster numerical parts of round 10 against what they replaced (issue 12 item 6).

- ARX least squares: Cholesky of the normal equations with iterative refinement (``ident.base._lstsq``)
  against the pivoted QR it replaced (``_lstsq_qr``, LAPACK gelsy), to 1e-10 relative on ARX designs as ill
  conditioned as the diagnosis' (lagged outputs of slow signals at 10 kHz) and on random designs; a
  rank-deficient design takes the QR itself.
- The caches of the plane operator's output (``models.hysteresis.plane_parts``) and of the dynamics refit
  (``ident.base.fit_dynamics``): a hit returns exactly what the computation returns, a changed input misses.
"""

import types

import numpy as np
import pytest
from scipy import signal as sig

from piezoctl.ident import base as B
from piezoctl.models import hysteresis as hy

REL = 1e-10


def _rel(new, ref) -> float:
    return float(np.max(np.abs(np.asarray(new) - np.asarray(ref))) / max(float(np.max(np.abs(ref))), 1e-300))


def _slow_io(rng, n, fs=1e4):
    """Input and output like the base's dynamics fit: a slow random walk and a 3 Hz to 300 Hz chirp through a
    lightly damped mode at ``fs`` (lagged outputs nearly collinear), with sensor noise."""
    walk = np.cumsum(np.repeat(rng.normal(0, 1.0, n // 2000 + 1), 2000)[:n]) / 40.0
    t = np.arange(n) / fs
    chirp = 0.3 * np.sin(2 * np.pi * (3 * t + 0.5 * 297 / t[-1] * t ** 2))
    x = walk + chirp
    w0, z = 2 * np.pi * rng.uniform(300, 1500), rng.uniform(0.02, 0.2)
    b, a = sig.cont2discrete(([w0 ** 2], [1, 2 * z * w0, w0 ** 2]), 1 / fs, method="zoh")[:2]
    y = sig.lfilter(np.ravel(b), a, x) + rng.normal(0, 1e-4, n)
    return x, y


def _arx_design(xs, ys, order, rows):
    """The design and target of ``ident.base._arx`` (same rows and columns)."""
    Xs, yy = [], []
    for x, y in zip(xs, ys):
        k = np.arange(order, y.size)
        if k.size > rows:
            k = k[:: int(np.ceil(k.size / rows))]
        Xs.append(np.column_stack([-y[k - i] for i in range(1, order + 1)] + [x[k - i] for i in range(order + 1)]
                                  + [np.ones(k.size)]))
        yy.append(y[k])
    return np.vstack(Xs), np.concatenate(yy)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("order", (2, 4, 6))
def test_arx_least_squares_matches_pivoted_qr(seed, order):
    rng = np.random.default_rng(seed)
    xs, ys = zip(*[_slow_io(rng, 60_000) for _ in range(3)])
    X, y = _arx_design(xs, ys, order, 40_000)
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    assert np.linalg.cond(X / sc) > 1e3          # as ill conditioned as the diagnosis' designs
    assert _rel(B._lstsq(X, y), B._lstsq_qr(X, y)) <= REL


@pytest.mark.parametrize("seed", range(4))
def test_arx_least_squares_random_designs(seed):
    rng = np.random.default_rng(10 + seed)
    X = rng.normal(size=(5000, 9)) * rng.uniform(1e-3, 1e3, 9)
    y = X @ rng.normal(size=9) + rng.normal(0, 0.1, 5000)
    assert _rel(B._lstsq(X, y), B._lstsq_qr(X, y)) <= REL


def test_rank_deficient_design_takes_the_qr():
    rng = np.random.default_rng(5)
    X = rng.normal(size=(3000, 4))
    X = np.column_stack([X, X[:, 1] + X[:, 2]])     # exactly dependent: the normal equations are singular
    y = rng.normal(size=3000)
    assert np.array_equal(B._lstsq(X, y), B._lstsq_qr(X, y))


@pytest.mark.parametrize("seed", range(3))
def test_arx_models_unchanged(seed):
    """The ARX models (b, a) of every order as with the QR (the drive-side refits use the fast path)."""
    rng = np.random.default_rng(20 + seed)
    xs, ys = zip(*[_slow_io(rng, 50_000) for _ in range(2)])
    for order in (2, 4, 6):
        new = B._arx(list(xs), list(ys), order, 30_000, fast=True)
        old = B._arx(list(xs), list(ys), order, 30_000)
        assert (new is None) == (old is None)
        if old is not None:
            for p, q in zip(new, old):
                assert _rel(p, q) <= REL


def test_fit_dynamics_cache_hits_only_the_same_data():
    rng = np.random.default_rng(7)
    xs, ys = zip(*[_slow_io(rng, 30_000) for _ in range(2)])
    xs, ys, k0s = list(xs), list(ys), [1000, 1000]
    B._DYN_CACHE.clear()
    ref = B._select_dynamics(xs, ys, k0s, 20_000, refine=False, band=0.01, orders=(4,), fast=True)[0]
    m1 = B.fit_dynamics(xs, ys, k0s, 20_000, band=0.01, orders=(4,))
    m2 = B.fit_dynamics([x.copy() for x in xs], [y.copy() for y in ys], k0s, 20_000, band=0.01, orders=(4,))
    assert m2 is m1 and len(B._DYN_CACHE) == 1
    assert all(np.array_equal(p, q) for p, q in zip(m1, ref))
    assert not m1[0].flags.writeable
    y2 = [ys[0].copy(), ys[1]]
    y2[0][12345] += 1e-12                              # one sample, one ulp-sized change: another key
    B.fit_dynamics(xs, y2, k0s, 20_000, band=0.01, orders=(4,))
    B.fit_dynamics(xs, ys, k0s, 20_000, band=0.02, orders=(4,))
    B.fit_dynamics(xs, ys, k0s, 20_000, band=0.01, orders=(2,))
    assert len(B._DYN_CACHE) == 4
    B._DYN_CACHE.clear()


def _plane(rng):
    r = [0.0, 0.1, 0.3, 0.6]
    knots = [np.linspace(-1 + ri, 1 - ri, 7).tolist() for ri in r]
    values = [np.concatenate([[0.0], np.cumsum(rng.uniform(0, 1, 6))]).tolist() for _ in r]
    return {"type": "plane", "r": r, "knots": knots, "values": values, "v_rest": 0.0, "offset": 1.5,
            "bw": {"beta": 4.0, "gamma": 1.0, "c_h": 0.2}}


def test_output_cache_is_exact(monkeypatch):
    rng = np.random.default_rng(8)
    v = np.cumsum(rng.normal(0, 0.01, 20_000))
    v = v / np.max(np.abs(v))
    hp = _plane(rng)
    hy.clear_output_cache()
    calls = []
    parts, plane = hy.hysteresis_parts, hy.plane_parts

    def compute(h, x):   # the reference, uncounted (a plane operator through plane_parts itself, as the cache)
        return plane(h, x) if h.get("type") == "plane" else parts(h, x)
    # every computation the cache makes is counted: plane operators through plane_parts (H only), others
    monkeypatch.setattr(hy, "hysteresis_parts", lambda h, x: calls.append(1) or parts(h, x))
    monkeypatch.setattr(hy, "plane_parts", lambda h, x, *a, **k: calls.append(1) or plane(h, x, *a, **k))
    h = hy.hysteresis_output(hp, v)
    assert np.array_equal(h, compute(hp, v)[0]) and not h.flags.writeable
    # the same drive (another array) and the same plane with another offset: a hit
    assert hy.hysteresis_output(dict(hp, offset=-3.0), v.copy()) is h and len(calls) == 1
    # a changed drive sample, a changed knot value, another Bouc-Wen weight, another operator type: misses
    v2 = v.copy()
    v2[777] += 1e-12
    hp2 = _plane(np.random.default_rng(8))
    hp2["values"][2][3] += 1e-9
    hp3 = dict(hp, bw=dict(hp["bw"], c_h=0.3))
    hp4 = {"type": "pi", "r": [0.0, 0.2], "w": [1.0, 0.5], "poly": [0.1, 0.0, 0.0], "v_lo": -1.0, "v_hi": 1.0}
    for hh, vv in ((hp, v2), (hp2, v), (hp3, v), (hp4, v)):
        assert np.array_equal(hy.hysteresis_output(hh, vv), compute(hh, vv)[0])
    assert len(calls) == 5
    # bounded; when full of one operator's outputs a new one of it is not stored, another operator's evicts
    hy.clear_output_cache()
    monkeypatch.setattr(hy, "_OUTPUT_CACHE_MAX_SAMPLES", 3 * v.size)
    for d in (0.0, 0.01, 0.02, 0.03):
        hy.hysteresis_output(hp, v + d)
    assert [k[1] for k in hy._OUTPUT_CACHE] == [v.size] * 3
    n = len(calls)
    assert np.array_equal(hy.hysteresis_output(hp, v + 0.03), compute(hp, v + 0.03)[0])   # not stored: again
    assert hy.hysteresis_output(hp, v + 0.01) is hy.hysteresis_output(hp, v + 0.01) and len(calls) == n + 1
    hy.hysteresis_output(hp2, v)
    assert len(hy._OUTPUT_CACHE) == 3 and sum(a.size for a in hy._OUTPUT_CACHE.values()) <= 3 * v.size
    assert next(reversed(hy._OUTPUT_CACHE))[0] == hy._output_key(hp2, v)[0]
    hy.clear_output_cache()
    assert not hy._OUTPUT_CACHE


@pytest.mark.parametrize("k", (1, 3, 8))
def test_prediction_on_test_rows_is_the_same_floats(k):
    """``select._fit_predict`` predicts every row and keeps the test rows: the floats of X[test] @ th."""
    rng = np.random.default_rng(k)
    X = rng.normal(size=(50_001, k)) * rng.uniform(0.1, 10, k)
    th = rng.normal(size=k)
    test = (np.arange(X.shape[0]) // 997) % 2 == 1
    assert np.array_equal((X @ th)[test], X[test] @ th)


def test_blas_threads_limits_and_restores():
    """``dsp.blas_threads`` sets every loaded OpenBLAS to n threads inside the block and restores it after, also
    when the block raises; the selection runs inside it."""
    import scipy.linalg  # noqa: F401  (loads scipy's own OpenBLAS besides numpy's)
    from piezoctl import dsp
    from piezoctl.diagnose import select as S
    ctl = dsp._openblas_controls()
    if not ctl:
        pytest.skip("no OpenBLAS loaded (another BLAS): nothing to limit")
    before = [g() for _, g in ctl]
    with pytest.raises(RuntimeError):
        with dsp.blas_threads(1):
            assert [g() for _, g in ctl] == [1] * len(ctl)
            raise RuntimeError("inside")
    assert [g() for _, g in ctl] == before
    seen = []

    class Probe:
        name = "probe"

        def applicable(self, ctx):
            seen.append([g() for _, g in ctl])
            return False
    S.select(types.SimpleNamespace(y_span=1.0), [Probe()], [], np.zeros(0), np.zeros(0), 0, 1000, 0.0, lambda *a: None)
    assert seen == [[1] * len(ctl)] and [g() for _, g in ctl] == before
