"""Round 23: in the drive-side group's discrimination (``discriminate.discriminate_group``), a candidate whose exact
fast residual exceeds the best's at the paired test's level is told apart even when another candidate is not
(the ambiguity holds among the others), and the selection (``select._discriminate``) refuses every candidate told
apart from the best. Synthetic per-sample high-passed residuals over 24 blocks."""

import types

import numpy as np

from piezoctl.diagnose import select as S
from piezoctl.diagnose.discriminate import discriminate_group

NB, M = 24, 400


def _blocks():
    blocks = np.repeat(np.arange(NB), M)
    return blocks % 2, blocks


def _residuals(seed):
    """Two candidates with the same fast residual (SD 1) and one with twice it (SD 2), the large one first."""
    rng = np.random.default_rng(seed)
    return [rng.normal(0, 2.0, NB * M), rng.normal(0, 1.0, NB * M), rng.normal(0, 1.0, NB * M)]


def _cands():
    return [types.SimpleNamespace(name=n, significant=True, veto=None, exact=None, discrimination=None,
                                  term=types.SimpleNamespace(group="drive_dynamics"))
            for n in ("amplifier_slew_limit", "delay", "amplifier_bandwidth")]


def test_one_told_apart_while_the_other_two_stay_ambiguous():
    fold, blocks = _blocks()
    apart = []
    order, text = discriminate_group(_cands(), _residuals(3), fold, blocks, 100.0, apart)
    assert text.startswith("Ambiguous")          # the delay and the pole are not told apart
    assert apart == [0]                          # the slew limit's residual is four times theirs
    assert order == [1, 2, 0]                    # behind the two, their order kept
    assert "amplifier_slew_limit leaves more than" in text
    assert "candidates delay, amplifier_bandwidth leave similar" in text


def test_nothing_told_apart_when_all_leave_the_same():
    fold, blocks = _blocks()
    rng = np.random.default_rng(4)
    apart = []
    order, text = discriminate_group(_cands(), [rng.normal(0, 1.0, NB * M) for _ in range(3)], fold, blocks, 100.0,
                                     apart)
    assert text.startswith("Ambiguous") and apart == [] and order == [0, 1, 2]
    assert "leaves more than" not in text


def test_clear_winner_tells_every_other_apart():
    fold, blocks = _blocks()
    rng = np.random.default_rng(5)
    hp = [rng.normal(0, 2.0, NB * M), rng.normal(0, 1.0, NB * M), rng.normal(0, 2.0, NB * M)]
    apart = []
    order, text = discriminate_group(_cands(), hp, fold, blocks, 100.0, apart)
    assert text.startswith("Discrimination") and order[0] == 1 and sorted(apart) == [0, 2]


def test_selection_refuses_the_candidates_told_apart(monkeypatch):
    fold, blocks = _blocks()
    hp = _residuals(3)
    cands = _cands()
    other = types.SimpleNamespace(name="creep", significant=True, veto=None, exact=None, discrimination=None,
                                  term=types.SimpleNamespace(group=None))
    evals = [cands[0], other, cands[1], cands[2]]
    # each candidate's exact model stands for its residual; highpassed returns it
    monkeypatch.setattr(S, "_exact_fold", lambda ctx, c, f, fold_all, recs: {"ys": c.name})
    by_name = {c.name: h for c, h in zip(cands, hp)}
    monkeypatch.setattr(S, "highpassed", lambda ctx, ys, fc: by_name[ys])
    S._discriminate(evals, [None, None], fold, blocks, None, 100.0, lambda *a: None)
    assert [c.name for c in evals] == ["delay", "creep", "amplifier_bandwidth", "amplifier_slew_limit"]
    assert cands[0].veto and "fast motion is not its shape" in cands[0].veto
    assert cands[1].veto is None and cands[2].veto is None and other.veto is None
