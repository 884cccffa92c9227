"""The diagnosis' faster numerical parts of round 11 against what they replaced (issue 12 item 6,
docs/diagnose-speed.md "Round 11").

- ``select._fit_predict``: unbounded fits solved from a Gram matrix assembled by blocks, the nuisance's block
  shared between settings (``_nuis_gram``), against the stacked least squares it replaced, to 1e-10 relative
  (coefficients, prediction, training error), with and without a nuisance, bounded and box-bounded fits too.
- ``significance.effective_n``: one FFT of length ``next_fast_len(n + lags)`` against the power of two >= 2n.
- ``ident.base.fit_base`` runs on one BLAS thread.
"""

import numpy as np
import pytest

from piezoctl.diagnose import select as S
from piezoctl.diagnose import significance as sg
from piezoctl.diagnose.solve import lstsq_box, train_rows

REL = 1e-10


def _rel(new, ref) -> float:
    ref = np.asarray(ref, float)
    return float(np.max(np.abs(np.asarray(new) - ref)) / max(float(np.max(np.abs(ref))), 1e-300))


def _old_fit_predict(X, e, train, test, rows, lb=None, nuis=None):
    """``select._fit_predict`` as of a9887ca (round 10): the stacked training rows [N, X] and their least squares."""
    def lstsq(X, y):
        sc = np.sqrt(np.mean(X ** 2, axis=0))
        sc[sc == 0] = 1.0
        Xs = X / sc
        th, *_ = np.linalg.lstsq(Xs.T @ Xs, Xs.T @ y, rcond=1e-12)
        return th / sc
    idx = train_rows(train, rows)
    Xtr = X[idx] if nuis is None else np.hstack([nuis[0], X[idx]])
    box = nuis is not None and len(nuis) > 2 and nuis[2] is not None
    if box:
        lo = np.concatenate([nuis[2][0], np.full(X.shape[1], -np.inf) if lb is None else np.asarray(lb, float)])
        hi = np.concatenate([nuis[2][1], np.full(X.shape[1], np.inf)])
        th = lstsq_box(Xtr, e[idx], lo, hi)
    else:
        if lb is not None and nuis is not None:
            lb = np.concatenate([np.full(nuis[0].shape[1], -np.inf), np.asarray(lb, float)])
        th = lstsq(Xtr, e[idx]) if lb is None else lstsq_box(Xtr, e[idx], lb, np.inf)
    sse_tr = float(np.sum((e[idx] - Xtr @ th) ** 2)) * (np.sum(train) / max(idx.size, 1))
    if nuis is None:
        return th, X[test] @ th, sse_tr
    m = nuis[1].shape[1]
    return th, nuis[1] @ th[:m] + X[test] @ th[m:], sse_tr


def _case(seed, n=60_000, k=4, m=5):
    """A residual, a design of k columns of very different scales and a nuisance of m columns correlated with
    it (as the hysteresis groups through the dynamics are with a term's regressors), folds of time blocks."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1e4
    N = np.column_stack([np.sin(2 * np.pi * (j + 1) * 0.7 * t) + 0.1 * rng.normal(size=n) for j in range(m)])
    X = np.column_stack([N[:, j % m] * 0.5 + rng.normal(size=n) * 10.0 ** (j - 2) for j in range(k)])
    e = X @ rng.normal(size=k) + N @ rng.normal(size=m) + 0.01 * rng.normal(size=n)
    fold = (np.arange(n) // 1000) % 2
    return X, e, N, fold == 0, fold == 1


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("kind", ("plain", "nuisance", "bounded", "bounded+nuisance", "box"))
def test_fit_predict_gram_matches_stacked_least_squares(seed, kind):
    X, e, N, train, test = _case(seed)
    rows = 20_000
    lb = np.array([0.0, -np.inf, 0.0, -np.inf]) if "bounded" in kind else None
    nuis = None
    if kind != "plain" and kind != "bounded":
        idx = train_rows(train, rows)
        bounds = (np.full(N.shape[1], -1.0), np.full(N.shape[1], 1.0)) if kind == "box" else None
        nuis = (N[idx], N[test], bounds)
    S._NUIS_GRAM.clear()
    ref = _old_fit_predict(X, e, train, test, rows, lb, nuis)
    for _ in range(2):   # the second call takes the nuisance's block from the cache
        new = S._fit_predict(X, e, train, test, rows, lb, nuis)
        assert _rel(new[0], ref[0]) < REL
        assert _rel(new[1], ref[1]) < REL
        assert abs(new[2] - ref[2]) <= REL * ref[2]


def test_nuisance_gram_cache_needs_the_same_arrays():
    X, e, N, train, test = _case(7)
    rows = 20_000
    idx = train_rows(train, rows)
    Ntr = N[idx]
    S._NUIS_GRAM.clear()
    a = S._nuis_gram(Ntr, e, idx)
    assert S._nuis_gram(Ntr, e, idx) is not None and S._NUIS_GRAM["last"][0] is Ntr
    e2 = e.copy()
    e2[idx[5]] += 1.0                     # another residual: its own products
    b = S._nuis_gram(Ntr, e2, idx)
    assert not np.array_equal(a[1], b[1])
    assert np.array_equal(b[1], Ntr.T @ e2[idx])
    N2 = Ntr.copy()
    N2[3, 0] += 1.0                       # another nuisance: its own products
    c = S._nuis_gram(N2, e2, idx)
    assert np.array_equal(c[0], N2.T @ N2)


def _old_effective_n(e, max_lag=2000):
    e = np.asarray(e, float) - np.mean(e)
    n = e.size
    if n < 4 or np.var(e) == 0:
        return float(max(n, 1))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(e, m)
    ac = np.fft.irfft(f * np.conj(f), m)[: min(max_lag, n - 1)]
    ac = ac / ac[0]
    neg = np.flatnonzero(ac < 0.05)
    cut = int(neg[0]) if neg.size else ac.size
    return float(max(1.0, n / max(1.0 + 2.0 * float(np.sum(ac[1:cut])), 1.0)))


@pytest.mark.parametrize("n", (4, 5, 17, 1000, 4097, 65_537, 300_001))
@pytest.mark.parametrize("max_lag", (2, 7, 2000))
def test_effective_n_matches_the_power_of_two_fft(n, max_lag):
    rng = np.random.default_rng(n + max_lag)
    for x in (rng.normal(size=n), np.cumsum(rng.normal(size=n)),
              np.convolve(rng.normal(size=n), np.ones(40) / 40, "same")):
        assert abs(sg.effective_n(x, max_lag) - _old_effective_n(x, max_lag)) <= REL * _old_effective_n(x, max_lag)


def test_fit_base_runs_on_one_blas_thread(monkeypatch):
    """``fit_base`` runs inside ``dsp.blas_threads(1)`` (restored after)."""
    import scipy.linalg  # noqa: F401
    from piezoctl import dsp
    from piezoctl.ident import base as B
    ctl = dsp._openblas_controls()
    if not ctl:
        pytest.skip("no OpenBLAS loaded (another BLAS): nothing to limit")
    before = [g() for _, g in ctl]
    seen = []

    def probe(*a, **k):
        seen.append([g() for _, g in ctl])
        raise RuntimeError("probe")
    monkeypatch.setattr(B, "_output_sign", probe)
    rec = type("R", (), {})()
    rng = np.random.default_rng(0)
    rec.sample_rate_hz, rec.u = 1e4, np.cumsum(rng.normal(size=20_000))
    rec.y = rec.u.copy()
    with pytest.raises(RuntimeError, match="probe"):
        B.fit_base([rec])
    assert seen == [[1] * len(ctl)] and [g() for _, g in ctl] == before


def test_design_stacks_the_settled_rows_exactly():
    """``select._Design`` copies each recording's settled rows straight into the stacked design: the same array
    as ``np.vstack`` of the masked regressors."""
    import types
    rng = np.random.default_rng(0)
    valid = [rng.random(n) > 0.3 for n in (1000, 50, 777)]
    Rs = [rng.normal(size=(v.size, 4)) for v in valid]
    ctx = types.SimpleNamespace(signals=[types.SimpleNamespace(i=i) for i in range(3)], valid=valid)
    d = S._Design(ctx, types.SimpleNamespace(regressors=lambda c, s, st: Rs[s.i]), 0)
    assert np.array_equal(d.X, np.vstack([R[v] for R, v in zip(Rs, valid)])) and d.k == 4


@pytest.mark.parametrize("bw", (True, False))
def test_plane_h_only_is_the_same_floats(bw):
    """``plane_parts(..., hysteretic=False)`` (what the output cache computes) gives H bit for bit."""
    from piezoctl.bench.diagnose_speed import _kernel_inputs, _plane_hp
    from piezoctl.models import hysteresis as hy
    hp = _plane_hp()
    if not bw:
        hp.pop("bw")
    v = _kernel_inputs(40_000, seed=2) * 1.2        # beyond the knots too
    h, y = hy.plane_parts(hp, v)
    h1, y1 = hy.plane_parts(hp, v, hysteretic=False)
    assert y1 is None and h1.tobytes() == h.tobytes()
    hy.clear_output_cache()
    assert hy.hysteresis_output(hp, v).tobytes() == h.tobytes()
    hy.clear_output_cache()


def test_filt_with_cached_initial_state_is_the_same_floats():
    """``dsp.filt`` takes ``lfilter_zi`` from a cache keyed on the exact coefficients: the same floats as the
    direct computation, another coefficient (one ulp) another entry."""
    from scipy import signal
    from piezoctl import dsp
    rng = np.random.default_rng(4)
    b, a = signal.butter(4, 0.05)
    x = np.cumsum(rng.normal(size=5000))
    X = rng.normal(size=(3000, 3))
    dsp._ZI_CACHE.clear()
    for _ in range(2):
        assert np.array_equal(dsp.filt(b, a, x), signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])[0])
        zi = signal.lfilter_zi(b, a)
        assert np.array_equal(dsp.filt(b, a, X), signal.lfilter(b, a, X, axis=0, zi=zi[:, None] * X[0][None, :])[0])
    assert len(dsp._ZI_CACHE) == 1
    b2 = b.copy()
    b2[0] = np.nextafter(b2[0], 1.0)
    assert np.array_equal(dsp.filt(b2, a, x), signal.lfilter(b2, a, x, zi=signal.lfilter_zi(b2, a) * x[0])[0])
    assert len(dsp._ZI_CACHE) == 2
