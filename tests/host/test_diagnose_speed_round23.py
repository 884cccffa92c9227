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
