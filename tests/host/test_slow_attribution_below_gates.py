"""Round 19: a slow candidate that can pass only below the first round's size gates and whose signature does not
hold is not the slow effect's name (slow_signature._unheld_below_gates), so it does not veto a holding one after it
in the precedence (development s117-004, creep + coupling, the coupling accepted first)."""

import types

from piezoctl.diagnose import select
from piezoctl.diagnose.slow_signature import attribute
from test_diagnose_slow import _test


def _cand(name, significant, folds, credited, p, below_gates):
    return types.SimpleNamespace(name=name, significant=significant, veto=None, fold_ratios=list(folds),
                                 credited=credited, dbic=-20.0, p=p, discrimination=None, slow_signature=None,
                                 below_gates=below_gates)


def _round(below_gates):
    """s117-004's second round: the offset passed (0.41/0.48), creep passed on its tail after the steps (all
    blocks 1.00/0.96), the drift's candidate is not significant (0.77/0.92) but the level trends within the
    recordings (t = -3.9); creep's signature holds (the step-locked tail), the drift's does not (unique 0.97)."""
    evals = [_cand("sensor_offset", True, (0.41, 0.48), 0.52, 3.6e-11, False),
             _cand("thermal_drift", False, (0.77, 0.92), 0.88, 0.76, below_gates),
             _cand("creep", True, (1.00, 0.96), 0.98, 2.2e-7, below_gates)]
    creep, drift, off = _test("creep", True, 1.04), _test("thermal_drift", False, 0.97), _test("sensor_offset", True, 0.44)
    drift.trend = off.trend = {"trends": True, "t": -3.9, "slope_um_per_s": -0.0208, "se_um_per_s": 0.0053,
                               "dof": 34, "p": 4.2e-4, "recordings": [0, 1, 2, 3], "levels_um": [-0.50],
                               "needed_um_per_s": [-0.0153], "quantile": 2.73, "excludes_drift": False,
                               "against_level": False, "same_shape": [], "pair_level": None}
    return evals, [creep, drift, off]


def _named(evals):
    return [c.name for c in evals if c.significant and not c.veto]


def test_below_the_gates_an_unheld_drift_does_not_veto_a_holding_creep():
    evals, tests = _round(below_gates=True)
    text = attribute(evals, tests)
    select._slow_beyond_gates(evals, lambda *a: None)
    assert _named(evals) == ["creep"], text
    assert evals[0].name == "creep" and "signature of creep holds" in text
    assert "attributed to creep" in next(c for c in evals if c.name == "sensor_offset").veto


def test_in_the_first_round_the_trending_drift_still_takes_the_offsets_level():
    """Round 15's rule is unchanged where the first round's gates apply: the drift is the name, creep vetoed."""
    evals, tests = _round(below_gates=False)
    attribute(evals, tests)
    select._slow_beyond_gates(evals, lambda *a: None)
    assert _named(evals) == ["thermal_drift"]
    assert "attributed to thermal_drift" in next(c for c in evals if c.name == "creep").veto
