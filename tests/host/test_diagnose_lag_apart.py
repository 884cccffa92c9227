"""Round 27: in the drive-side group's discrimination, the delay and the amplifier's pole (``select.LAG_PAIR``) refused
only because the other lag left less fast residual are checked on their own when that other lag's shape check fails
(``select._lift_lag_apart``); a slew limit's refusal stays. Synthetic per-sample high-passed residuals over 24 blocks,
as ``test_diagnose_discriminate_apart.py``."""

import types

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.diagnose.discriminate import discriminate_group

NB, M = 24, 400


def _blocks():
    blocks = np.repeat(np.arange(NB), M)
    return blocks % 2, blocks


def _cands():
    return [types.SimpleNamespace(name=n, significant=True, veto=None, exact=None, discrimination=None,
                                  lag_apart_from=None, term=types.SimpleNamespace(group="drive_dynamics"))
            for n in ("amplifier_slew_limit", "delay", "amplifier_bandwidth")]


def _discriminated(monkeypatch, sds):
    """The three candidates discriminated on residuals of the given SDs (slew limit, delay, pole)."""
    fold, blocks = _blocks()
    rng = np.random.default_rng(7)
    cands = _cands()
    by_name = {c.name: rng.normal(0, sd, NB * M) for c, sd in zip(cands, sds)}
    monkeypatch.setattr(S, "_exact_fold", lambda ctx, c, f, fold_all, recs: {"ys": c.name})
    monkeypatch.setattr(S, "highpassed", lambda ctx, ys, fc: by_name[ys])
    evals = list(cands)
    S._discriminate(evals, [None, None], fold, blocks, None, 100.0, lambda *a: None)
    return cands, evals


def test_best_out_names_the_least_residual():
    fold, blocks = _blocks()
    rng = np.random.default_rng(5)
    best = []
    discriminate_group(_cands(), [rng.normal(0, s, NB * M) for s in (2.0, 2.0, 1.0)], fold, blocks, 100.0, [], best)
    assert best == [2]


def test_the_pole_s_failed_shape_lifts_the_delay_s_refusal_but_not_the_slew_limit_s(monkeypatch):
    (slew, delay, pole), evals = _discriminated(monkeypatch, (2.0, 2.0, 1.0))
    assert evals[0] is pole
    assert "group's least" in delay.veto and "group's least" in slew.veto
    assert delay.lag_apart_from == "amplifier_bandwidth" and slew.lag_apart_from is None
    pole.veto = "its signature check fails: ..."
    S._lift_lag_apart(evals, pole, lambda *a: None)
    assert delay.veto is None                      # checked on its own shape next
    assert "amplifier_bandwidth, which left less fast residual, failed its own shape check" in delay.discrimination
    assert slew.veto and "group's least" in slew.veto


def test_the_delay_s_failed_shape_lifts_the_pole_s_refusal(monkeypatch):
    (slew, delay, pole), evals = _discriminated(monkeypatch, (2.0, 1.0, 2.0))
    assert pole.lag_apart_from == "delay"
    S._lift_lag_apart(evals, delay, lambda *a: None)
    assert pole.veto is None and "group's least" in slew.veto


def test_nothing_lifted_when_the_failed_shape_is_not_the_refusing_lag_s(monkeypatch):
    (slew, delay, pole), evals = _discriminated(monkeypatch, (1.0, 2.0, 2.0))   # the slew limit is the least
    assert delay.lag_apart_from is None and pole.lag_apart_from is None
    S._lift_lag_apart(evals, slew, lambda *a: None)
    assert "group's least" in delay.veto and "group's least" in pole.veto


def test_another_refusal_of_the_partner_stays(monkeypatch):
    (slew, delay, pole), evals = _discriminated(monkeypatch, (2.0, 2.0, 1.0))
    delay.veto = "its shape is the amplifier_bandwidth's: ..."   # e.g. a later gate's
    S._lift_lag_apart(evals, pole, lambda *a: None)
    assert delay.veto.startswith("its shape is")
