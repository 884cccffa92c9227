"""The diagnosis' faster parts of round 13 against what they replaced, bit for bit (issue 12 item 6,
docs/diagnose-speed.md "Round 13").

- ``significance.unique_labels``: ``np.unique`` of a label array by its runs when it is non-decreasing;
- ``locate.residual_autocorrelation``: the first lags by one dot product each instead of ``np.correlate``'s
  full correlation;
- ``terms.G_of_h``: ``G(ctx.base, s.h)`` kept per signal and model, recomputed for another model or signal;
- ``hysteresis.plane_parts`` with its larger blocks: the same H as one block (the recursion restarts exactly).
"""

import types

import numpy as np
import pytest

from piezoctl.diagnose import locate
from piezoctl.diagnose import significance as sg
from piezoctl.ident import terms
from piezoctl.models import hysteresis as hy


def _labels(rng, n, sort):
    x = rng.integers(-3, 40, n)
    return np.sort(x) if sort else x


@pytest.mark.parametrize("sort", [True, False])
@pytest.mark.parametrize("n", [1, 2, 7, 500, 20_000])
def test_unique_labels_equals_np_unique(sort, n):
    rng = np.random.default_rng(n + sort)
    x = _labels(rng, n, sort)
    for flags in [(False, False, False), (True, False, True), (False, True, False), (True, True, True)]:
        got = sg.unique_labels(x, *flags)
        ref = np.unique(x, *flags)
        got = got if isinstance(got, tuple) else (got,)
        ref = ref if isinstance(ref, tuple) else (ref,)
        assert len(got) == len(ref)
        for a, b in zip(got, ref):
            assert a.shape == b.shape and np.array_equal(a, b)


def test_unique_labels_falls_back_for_floats_and_2d():
    x = np.array([0.0, 0.0, 1.0, 3.0])
    assert np.array_equal(sg.unique_labels(x), np.unique(x))
    y = np.array([[2, 1], [1, 0]])
    assert np.array_equal(sg.unique_labels(y), np.unique(y))


def _old_autocorrelation(r, dt, max_lag=25, max_n=20000):
    """``locate.residual_autocorrelation`` as of a961178 (round 12): the full ``np.correlate``."""
    step = max(1, int(round(1e-3 / dt)))
    rd = np.asarray(r)[::step]
    n = rd.size
    if n < 64:
        return None
    m = min(n, max_n)
    rr = rd - rd.mean()
    ac = np.correlate(rr[:m], rr[:m], "full")
    ac = ac[m - 1: m + max_lag] / (ac[m - 1] or 1.0)
    return np.arange(ac.size) * step * dt, ac, 2.58 / np.sqrt(n)


@pytest.mark.parametrize("n", [640, 12_345, 400_000])
def test_residual_autocorrelation_bit_for_bit(n):
    rng = np.random.default_rng(n)
    r = np.cumsum(rng.normal(size=n)) * 1e-3 + rng.normal(size=n) * 1e-4   # slow and white parts, as a residual
    new, old = locate.residual_autocorrelation(r, 1e-4), _old_autocorrelation(r, 1e-4)
    for a, b in zip(new, old):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    assert locate.residual_autocorrelation(r[:500], 1e-4) is None   # 50 decimated samples: too few, as before


def _ctx_and_signal(seed=0):
    rng = np.random.default_rng(seed)
    base = {"dynamics": {"b": [0.02, 0.01], "a": [1.0, -0.97]}}
    s = types.SimpleNamespace(h=np.cumsum(rng.normal(size=5000)))
    return types.SimpleNamespace(base=base, refit_cache={}), s


def test_g_of_h_bit_for_bit_and_kept():
    ctx, s = _ctx_and_signal()
    g = terms.G_of_h(ctx, s)
    assert np.array_equal(g, terms.G(ctx.base, s.h))
    assert terms.G_of_h(ctx, s) is g                  # kept: the same array
    assert not g.flags.writeable


def test_g_of_h_recomputes_for_another_model_or_signal():
    ctx, s = _ctx_and_signal()
    g = terms.G_of_h(ctx, s)
    ctx.base = {"dynamics": {"b": [0.03], "a": [1.0, -0.97]}}   # another model sharing the dict
    g2 = terms.G_of_h(ctx, s)
    assert g2 is not g and np.array_equal(g2, terms.G(ctx.base, s.h))
    s2 = types.SimpleNamespace(h=s.h * 2.0)
    g3 = terms.G_of_h(ctx, s2)
    assert np.array_equal(g3, terms.G(ctx.base, s2.h)) and not np.array_equal(g3, g2)


def test_plane_blocks_give_one_blocks_floats(monkeypatch):
    """The block length only decides where the plays' recursion restarts from its last outputs: the default
    (65,536) and one block give the same H, bit for bit, on a drive of 200 k samples (four blocks)."""
    from piezoctl.bench.diagnose_speed import _kernel_inputs, _plane_hp
    v = _kernel_inputs(200_000)
    hp = _plane_hp()
    hy._STATE_CACHE.clear()
    h_blocks = hy.plane_parts(hp, v, hysteretic=False)[0]
    monkeypatch.setattr(hy, "_PLANE_BLOCK", 10 ** 7)
    hy._STATE_CACHE.clear()
    h_one = hy.plane_parts(hp, v, hysteretic=False)[0]
    hy._STATE_CACHE.clear()
    assert hy._PLANE_BLOCK == 10 ** 7 and np.array_equal(h_blocks, h_one)


def test_hysteresis_output_of_same_floats_and_skips_the_drive():
    """A recurring (tag, anchor) finds H without computing its drive again; another anchor (an equal copy), another
    operator or an emptied cache computes it; the floats are hysteresis_output's."""
    from piezoctl.bench.diagnose_speed import _kernel_inputs, _plane_hp
    hy.clear_output_cache()
    u = _kernel_inputs(50_000)
    hp = _plane_hp()
    calls = []

    def make_v(x=u):
        calls.append(1)
        return np.clip(x, -0.5, 0.5)
    h = hy.hysteresis_output_of(hp, ("saturation", "(-0.5, 0.5)"), u, make_v)
    assert np.array_equal(h, hy.hysteresis_output(hp, np.clip(u, -0.5, 0.5))) and len(calls) == 1
    assert hy.hysteresis_output_of(hp, ("saturation", "(-0.5, 0.5)"), u, make_v) is h and len(calls) == 1
    u_copy = u.copy()
    assert np.array_equal(hy.hysteresis_output_of(hp, ("saturation", "(-0.5, 0.5)"), u_copy,
                                                  lambda: make_v(u_copy)), h) and len(calls) == 2
    hp2 = dict(hp, values=[list(np.asarray(x) * 2.0) for x in hp["values"]])
    h2 = hy.hysteresis_output_of(hp2, ("saturation", "(-0.5, 0.5)"), u, make_v)
    assert len(calls) == 3 and np.array_equal(h2, hy.hysteresis_output(hp2, np.clip(u, -0.5, 0.5)))
    hy.clear_output_cache()
    hy.hysteresis_output_of(hp, ("saturation", "(-0.5, 0.5)"), u, make_v)
    assert len(calls) == 4
    hy.clear_output_cache()


def test_hysteresis_output_of_unchanged_drive():
    """make_v returning None (the drive unchanged) gives None, remembered for the tag."""
    hy.clear_output_cache()
    u = np.linspace(-1, 1, 1000)
    calls = []
    assert hy.hysteresis_output_of({"type": "plane"}, ("x",), u, lambda: calls.append(1)) is None
    assert hy.hysteresis_output_of({"type": "plane"}, ("x",), u, lambda: calls.append(1)) is None
    assert len(calls) == 1
    hy.clear_output_cache()


def test_hysteresis_output_of_one_tag_for_several_recordings():
    """One tag (a term's setting) on several recordings' drives: each recording keeps its own entry, so a recurring
    setting skips every recording's drive (round 13's first version keyed the tag alone: the recordings evicted
    each other and 1027 of 1029 drives on s0-017 were recomputed)."""
    hy.clear_output_cache()
    hp = {"type": "plane", "r": [0.0, 0.3], "knots": [[-1.0, 1.0], [-0.7, 0.7]], "values": [[0.0, 2.0], [0.0, 0.5]]}
    us = [np.sin(np.linspace(0, 20, 3000) * (k + 1)) for k in range(3)]
    calls = []

    def make(u):
        calls.append(1)
        return np.clip(u, -0.8, 0.8)
    first = [hy.hysteresis_output_of(hp, ("saturation", "0.8"), u, lambda u=u: make(u)) for u in us]
    again = [hy.hysteresis_output_of(hp, ("saturation", "0.8"), u, lambda u=u: make(u)) for u in us]
    assert len(calls) == 3 and all(a is b for a, b in zip(first, again))
    assert all(np.array_equal(h, hy.hysteresis_output(hp, np.clip(u, -0.8, 0.8))) for h, u in zip(first, us))
    hy.clear_output_cache()
