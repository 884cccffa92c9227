"""Round 27: a map of the reading (the sensor curve) accepted in a round where a slow term (creep, drift, offset) is
significant too is put after the slow term when the slow term's exact model lowers the pooled held-out error more;
otherwise it stays first. A term that is not a map of the reading is never reordered."""

from piezoctl.diagnose import select
from piezoctl.ident.terms import TERMS


def _cand(name, before, after, significant=True, veto=None):
    return select.Candidate(term=TERMS[name], ratio=0.6, fold_ratios=[0.6, 0.6], nrmse_before=before,
                            nrmse_after=after, t=5.0, p=1e-8, n_active=40, p_max=1e-3, dbic=-40.0, n_eff=500.0,
                            significant=significant, setting=[None, None], coef=[None, None], credited=0.6,
                            veto=veto, exact_before=before, exact_after=after)


def _run(best, evals, monkeypatch, passes=True):
    # the exact check needs a real context; here a slow candidate passes it (or not) with the figures it carries
    seen = []

    def first(cands, *a, **k):
        seen.append(cands[0].name)
        return cands[0] if passes else None
    monkeypatch.setattr(select, "_first_exact", first)
    return select._slow_before_map(best, evals, None, None, None, 1.0, lambda *_: None, None), seen


def test_exact_ratio():
    assert select.exact_ratio(_cand("creep", 0.02, 0.005)) == 0.25
    c = _cand("creep", 0.02, 0.005)
    c.exact_before = None
    assert select.exact_ratio(c) == 1.0


def test_creep_explaining_more_goes_first(monkeypatch):
    # s137-000's shape: the curve passes at an exact ratio 0.84, creep's model on the dwells reaches 0.25
    curve, creep = _cand("sensor_nonlinearity", 0.0224, 0.0189), _cand("creep", 0.0224, 0.0056)
    evals = [curve, creep]
    got, seen = _run(curve, evals, monkeypatch)
    assert got is creep and evals == [creep, curve] and seen == ["creep"]
    assert "tested again beside it" in creep.discrimination


def test_curve_explaining_more_stays_first(monkeypatch):
    curve, drift = _cand("sensor_nonlinearity", 0.02, 0.008), _cand("thermal_drift", 0.02, 0.018)
    evals = [curve, drift]
    got, _ = _run(curve, evals, monkeypatch)
    assert got is curve and evals == [curve, drift]


def test_slow_term_refused_by_its_exact_check_does_not_displace(monkeypatch):
    curve, offset = _cand("sensor_nonlinearity", 0.02, 0.016), _cand("sensor_offset", 0.02, 0.004)
    got, seen = _run(curve, [curve, offset], monkeypatch, passes=False)
    assert got is curve and seen == ["sensor_offset"]


def test_insignificant_or_vetoed_slow_terms_are_not_tried(monkeypatch):
    curve = _cand("sensor_nonlinearity", 0.02, 0.016)
    evals = [curve, _cand("creep", 0.02, 0.004, significant=False), _cand("thermal_drift", 0.02, 0.004, veto="no")]
    got, seen = _run(curve, evals, monkeypatch)
    assert got is curve and seen == []


def test_other_terms_are_not_reordered(monkeypatch):
    asym, creep = _cand("asymmetric_hysteresis", 0.02, 0.016), _cand("creep", 0.02, 0.004)
    got, seen = _run(asym, [asym, creep], monkeypatch)
    assert got is asym and seen == []


def _pair(name, verdict, nb_p=0.9, ab_p=1e-7):
    t = lambda p: {"p": p, "fold_ratios": [0.97, 0.98] if p > 0.01 else [0.45, 0.38], "n_active": 30,  # noqa: E731
                   "significant": p < 0.01}
    return {"name": name, "verdict": verdict, "named_alone": t(1e-9), "alternative_alone": t(1e-16),
            "named_beyond": t(nb_p), "alternative_beyond": t(ab_p)}


def test_map_refused_when_a_slow_term_explains_all_it_does():
    # s138-016's shape: the curve beyond the drift p 0.90, the drift beyond the curve p 1e-7 (verdict "b")
    curve = _cand("sensor_nonlinearity", 0.0116, 0.0080)
    curve.separation = [_pair("thermal_drift", "b")]
    why = select._map_within_slow(curve)
    assert why is not None and "thermal_drift" in why and "p = 9.0e-01" in why


def test_map_stands_when_it_holds_beyond_the_slow_term():
    curve = _cand("sensor_nonlinearity", 0.02, 0.01)
    curve.separation = [_pair("creep", "a", nb_p=1e-9, ab_p=0.5), _pair("sensor_offset", "both", 1e-5, 1e-5)]
    assert select._map_within_slow(curve) is None
    curve.separation = None
    assert select._map_within_slow(curve) is None


def test_map_not_refused_for_a_drive_side_alternative():
    # a verdict "b" of a drive-side term is _prefer_containing's question (that term must pass its own gates)
    curve = _cand("sensor_nonlinearity", 0.02, 0.01)
    curve.separation = [_pair("delay", "b")]
    assert select._map_within_slow(curve) is None


def test_other_terms_not_refused_by_a_slow_pair():
    asym = _cand("asymmetric_hysteresis", 0.02, 0.01)
    asym.separation = [_pair("creep", "b")]
    assert select._map_within_slow(asym) is None
