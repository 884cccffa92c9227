"""The faster kernels of round 9 against the plain formulas they replaced, on random inputs.

Interpolation and the plane operator may differ by round-off only (1e-12 of the output's scale); the play
operators and the slew limiter compute the same recursion and must agree bit for bit. The reference
implementations below are the straightforward, sample-by-sample or segment-formula versions.
"""

import numpy as np
import pytest

from piezoctl import dsp
from piezoctl.models import hysteresis as hy
from piezoctl.models.play import play_outputs

REL = 1e-12


def _close(new, ref, rel=REL):
    scale = max(1.0, float(np.max(np.abs(ref)))) if np.size(ref) else 1.0
    err = float(np.max(np.abs(np.asarray(new) - np.asarray(ref)))) if np.size(ref) else 0.0
    assert err <= rel * scale, f"max |new - ref| = {err:.3g} > {rel:g} x {scale:.3g}"


# --- reference implementations (the formulas before round 9) -------------------------------------------

def ref_interp(x, knots, values):
    """values[i] (1 - f) + values[i+1] f on the segment i of each x (found by search), f beyond [0, 1] outside."""
    k = np.asarray(knots, float)
    x = np.asarray(x, float)
    vals = np.asarray(values, float)
    i = np.clip(np.searchsorted(k, x, side="right") - 1, 0, k.size - 2)
    f = (x - k[i]) / (k[i + 1] - k[i])
    return vals[i] * (1.0 - f) + vals[i + 1] * f


def ref_play(u, r, y0):
    """F(k) = max(u(k) - r, min(u(k) + r, F(k-1))), sample by sample."""
    f = np.array(y0, float)
    out = np.empty((u.size, r.size))
    for k, x in enumerate(u):
        f = np.maximum(x - r, np.minimum(x + r, f))
        out[k] = f
    return out


def ref_plane_parts(hp, v):
    r = np.asarray(hp["r"], float)
    P = ref_play(v, r, np.full(r.size, float(hp.get("v_rest", 0.0))))
    h = np.zeros(v.size)
    hyst = np.zeros(v.size)
    for j, (kn, vals) in enumerate(zip(hp["knots"], hp["values"])):
        fj = ref_interp(P[:, j], kn, vals)
        h += fj
        if r[j] > 0:
            hyst += fj - ref_interp(v, kn, vals)
    bw = hp.get("bw")
    if bw:
        hb = float(bw["c_h"]) * hy._bouc_wen_h(v, float(bw["beta"]), float(bw["gamma"]), float(hp.get("v_rest", 0.0)))
        h, hyst = h + hb, hyst + hb
    return h, hyst


def ref_slew(u, max_step):
    out = np.array(u, float)
    prev = float(out[0]) if out.size else 0.0
    for i in range(1, out.size):
        d = out[i] - prev
        if d > max_step:
            prev += max_step
        elif d < -max_step:
            prev -= max_step
        else:
            prev = float(out[i])
        out[i] = prev
    return out


# --- random inputs ------------------------------------------------------------------------------------

def _drive(rng, n):
    """A normalized drive: random walk, triangles, a chirp and steps (some beyond [-1, 1]), with noise."""
    q = n // 4
    t = np.arange(q) / 1e4
    walk = np.cumsum(rng.normal(0, 3e-3, q))
    walk = 1.1 * walk / max(1e-9, np.max(np.abs(walk)))
    tri = rng.uniform(0.5, 1.2) * (2 * np.abs(2 * ((t * rng.uniform(1, 20)) % 1.0) - 1) - 1)
    chirp = 0.8 * np.sin(2 * np.pi * (5 + 200 * t / t[-1]) * t)
    steps = np.repeat(rng.uniform(-1.2, 1.2, (n - 3 * q) // 50 + 1), 50)[:n - 3 * q]
    return np.concatenate([walk, tri, chirp, steps]) + rng.normal(0, rng.choice([0.0, 1e-4]), n)


def _plane(rng, even=True, bw=True):
    n_plays = int(rng.integers(2, 12))
    r = np.concatenate([[0.0], np.sort(rng.uniform(0.01, 0.9, n_plays - 1))])
    knots, values = [], []
    for ri in r:
        k = int(rng.integers(2, 22))
        if even:
            kn = np.linspace(-1.0 + ri, 1.0 - ri + 1e-3, k)
        else:
            kn = np.sort(rng.uniform(-1.0, 1.0, k))
            kn[0], kn[-1] = -1.0 + ri, 1.0 - ri + 1e-3
            kn = np.unique(kn)
        knots.append(kn.tolist())
        values.append(np.concatenate([[0.0], rng.normal(0, 3.0, kn.size - 1)]).tolist())
    hp = {"type": "plane", "r": r.tolist(), "knots": knots, "values": values, "v_rest": float(rng.uniform(-0.2, 0.2))}
    if bw:
        hp["bw"] = {"beta": float(rng.uniform(1, 10)), "gamma": float(rng.uniform(-0.5, 0.5)), "c_h": 0.3}
    return hp


# --- tests ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(6))
def test_interp_linear_ext_matches_segment_formula(seed):
    rng = np.random.default_rng(seed)
    x = _drive(rng, 20_000) * 1.5
    for even in (True, False):
        k = int(rng.integers(2, 30))
        kn = np.linspace(-0.9, 0.8, k) if even else np.unique(rng.uniform(-1, 1, k + 1))
        vals = rng.normal(0, 5.0, kn.size)
        _close(hy.interp_linear_ext(x, kn, vals), ref_interp(x, kn, vals))
        _close(hy.interp_linear_ext(x[::3], kn, vals), ref_interp(x[::3], kn, vals))   # a strided input
    # beyond both ends only, and no samples
    kn = np.array([0.0, 0.5, 1.0])
    _close(hy.interp_linear_ext(np.array([-3.0, 7.0]), kn, [1.0, 2.0, 0.0]), [-5.0, -24.0])
    assert hy.interp_linear_ext(np.zeros(0), kn, [1.0, 2.0, 0.0]).size == 0


def test_sum_of_pl_is_the_sum():
    rng = np.random.default_rng(7)
    ks = [np.linspace(-0.8, 0.7, 5), np.linspace(-0.3, 0.9, 9), np.sort(rng.uniform(-1, 1, 6))]
    vs = [rng.normal(size=k.size) for k in ks]
    kn, vals = hy._sum_of_pl(ks, vs)
    x = np.linspace(-2.0, 2.0, 4001)
    _close(hy.interp_linear_ext(x, kn, vals), sum(ref_interp(x, k, v) for k, v in zip(ks, vs)))


@pytest.mark.parametrize("seed", range(4))
def test_classical_play_bit_exact_in_both_layouts(seed):
    rng = np.random.default_rng(seed)
    u = _drive(rng, 8_000)
    r = np.sort(rng.uniform(0.0, 0.9, 7))
    y0 = rng.uniform(-0.3, 0.3, 7)
    ref = ref_play(u, r, y0)
    for order in ("C", "F"):
        out = play_outputs(u, r, y0=y0, order=order)
        assert out.flags[order + "_CONTIGUOUS"]
        assert np.array_equal(out, ref)
    # the unparallel path (a != 1) in column layout too
    a = rng.uniform(0.5, 1.5, 7)
    assert np.array_equal(play_outputs(u, r, a=a, y0=y0, order="F"), play_outputs(u, r, a=a, y0=y0))


def test_play_order_refused():
    with pytest.raises(ValueError, match="order"):
        play_outputs(np.zeros(3), [0.1], order="K")


@pytest.mark.parametrize("seed", range(5))
def test_plane_parts_match_reference(seed, monkeypatch):
    monkeypatch.setattr(hy, "_PLANE_BLOCK", 1000)   # many blocks, runs split across their boundaries
    rng = np.random.default_rng(100 + seed)
    v = _drive(rng, 12_000)
    for even, bw in ((True, True), (False, False)):
        hp = _plane(rng, even=even, bw=bw)
        hy._STATE_CACHE.clear()
        h, hyst = hy.plane_parts(hp, v)          # states computed block by block, not cached
        rh, rhyst = ref_plane_parts(hp, v)
        _close(h, rh)
        _close(hyst, rhyst)
        hy.play_states(v, hp["r"], hp["v_rest"])   # states cached: plane_parts takes them from the cache
        h2, hyst2 = hy.plane_parts(hp, v)
        assert np.array_equal(h2, h) and np.array_equal(hyst2, hyst)
        # channels and groups sum to H; the groups are the channels summed by group (the formula before round 9)
        C = hy.hysteresis_channels(hp, v)
        _close(C.sum(axis=1), rh)
        r = np.asarray(hp["r"])
        n = r.size
        ref_groups = [C[:, np.flatnonzero(r == 0)].sum(axis=1), C[:, np.flatnonzero(r > 0)].sum(axis=1)] + ([C[:, n]] if bw else [])
        G = hy.hysteresis_groups(hp, v)
        assert G.shape == (v.size, len(ref_groups))
        for g, rg in zip(G.T, ref_groups):
            _close(g, rg)


def test_state_cache_is_exact_under_crc_collisions(monkeypatch):
    """Every drive hashes alike: the cache must still return each drive's own state."""
    monkeypatch.setattr(hy.zlib, "crc32", lambda b: 0)
    hy._STATE_CACHE.clear()
    rng = np.random.default_rng(3)
    v1 = _drive(rng, 4000)
    v2 = v1.copy()
    v2[1234] += 1e-9
    r = [0.0, 0.2, 0.5]
    a1 = hy.play_states(v1, r)
    a2 = hy.play_states(v2, r)
    assert np.array_equal(a1, ref_play(v1, np.array(r), np.zeros(3)))
    assert np.array_equal(a2, ref_play(v2, np.array(r), np.zeros(3)))
    assert np.array_equal(hy.play_states(v1, r), a1)
    assert not hy.play_states(v1, r).flags.writeable
    hy._STATE_CACHE.clear()


def test_state_cache_hits_and_bounds(monkeypatch):
    hy._STATE_CACHE.clear()
    calls = []

    def compute(x):
        calls.append(1)
        return x * 2.0
    v = np.arange(1000.0)
    a = hy._cached_state("t", (), v, compute)
    b = hy._cached_state("t", (), v.copy(), compute)
    assert a is b and len(calls) == 1
    monkeypatch.setattr(hy, "_STATE_CACHE_MAX_SAMPLES", 5000)
    for k in range(5):
        hy._cached_state("t", (k,), v, compute)
    assert sum(x.size + y.size for x, y in hy._STATE_CACHE.values()) <= 5000
    hy._STATE_CACHE.clear()


@pytest.mark.parametrize("seed", range(6))
def test_slew_limit_bit_exact(seed):
    rng = np.random.default_rng(seed)
    u = 50.0 + 40.0 * _drive(rng, 30_000)
    for q in (0.0005, 0.01, 0.1, 0.5, 1.0):
        step = q * float(np.max(np.abs(np.diff(u))))
        assert np.array_equal(dsp.slew_limit(u, step), ref_slew(u, step)), q
    # a long ramp (one step over many chunks), a reversal during a ramp, zero and infinite limits
    u = np.concatenate([np.zeros(10), np.full(200_000, 1.0), np.full(50, -1.0), np.zeros(100)])
    for step in (1e-5, 3e-3, 0.0, np.inf):
        assert np.array_equal(dsp.slew_limit(u, step), ref_slew(u, step)), step
