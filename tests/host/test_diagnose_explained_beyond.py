"""Round 22: a beyond-range term its pair test found explained by the accepted one is not named after it."""
from types import SimpleNamespace as NS

from piezoctl.diagnose.select import _explained_beyond, _veto_explained
from piezoctl.ident.terms import AsymmetricHysteresis, Saturation, SensorNonlinearity


def _pair(name, verdict, alt_folds=(0.79, 0.86), alt_p=1.6e-5):
    t = lambda fr, p: {"p": p, "fold_ratios": list(fr), "n_active": 18, "significant": False}
    return {"name": name, "verdict": verdict, "named_alone": t((0.02, 0.02), 1e-17),
            "alternative_alone": t((0.2, 0.2), 1e-15), "named_beyond": t((0.1, 0.1), 1e-13),
            "alternative_beyond": t(alt_folds, alt_p)}


def _cand(name, term, significant=True, veto=None, separation=None):
    return NS(name=name, term=term, significant=significant, veto=veto, separation=separation, selection_round=1)


def test_clip_first_explains_the_knee_by_its_pair_verdict():
    best = _cand("saturation", Saturation, separation=[_pair("asymmetric_hysteresis", "a"),
                                                        _pair("sensor_nonlinearity", "a")])
    knee, curve = _cand("asymmetric_hysteresis", AsymmetricHysteresis), _cand("sensor_nonlinearity", SensorNonlinearity)
    ex = _explained_beyond(best, [best, knee, curve])
    # only the other beyond-range term of verdict "a"; the sensor curve acts in range too and stays offered
    assert set(ex) == {"asymmetric_hysteresis"}
    assert "0.79/0.86" in ex["asymmetric_hysteresis"]
    lines = []
    _veto_explained([knee, curve], ex, lines.append)
    assert not knee.significant and knee.veto == ex["asymmetric_hysteresis"]
    assert curve.significant and curve.veto is None
    assert len(lines) == 1


def test_other_verdicts_and_terms_leave_the_later_rounds_alone():
    ev = [_cand("asymmetric_hysteresis", AsymmetricHysteresis), _cand("saturation", Saturation)]
    for v in ("both", "inseparable", "b", "neither"):
        assert _explained_beyond(_cand("saturation", Saturation, separation=[_pair("asymmetric_hysteresis", v)]), ev) == {}
    # a first term that acts in range too: its pair verdicts do not answer a beyond-range question
    assert _explained_beyond(_cand("sensor_nonlinearity", SensorNonlinearity,
                                   separation=[_pair("asymmetric_hysteresis", "a")]), ev) == {}
    assert _explained_beyond(_cand("saturation", Saturation, separation=None), ev) == {}
    # a slow pair's record without the four tests (slow_signature's "reason") is skipped
    assert _explained_beyond(_cand("saturation", Saturation,
                                   separation=[{"name": "asymmetric_hysteresis", "verdict": "a", "reason": "x"}]), ev) == {}
