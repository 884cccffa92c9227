"""bench.effect_oracle.branch_ratios (round 25): the kept base plus a mode's own branch, at a fixed gain and with
its gains least-squared."""

import numpy as np
import pytest

from piezoctl.bench.effect_oracle import branch_ratios
from piezoctl.ident.terms import UnmodeledResonance

DT = 1e-4


def _steps(n=20000, seed=0):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(0.0, 10.0, n // 500), 500)   # um: steps that ring a mode


def test_the_true_branch_takes_an_error_that_is_the_branch():
    w = _steps()
    cols = UnmodeledResonance.basis(w, 2000.0, 0.02, DT)
    noise = np.random.default_rng(1).normal(0.0, 1e-4, w.size)
    resid = -0.05 * cols[:, 0] + noise
    fixed, fit = branch_ratios(resid, cols, -0.05)
    assert fixed < 0.05 and fit < 0.05
    # the wrong sign doubles the error (-0.05 c - 0.05 c); the fitted gains still find it
    wrong, fit2 = branch_ratios(resid, cols, +0.05)
    assert wrong == pytest.approx(2.0, rel=0.01)
    assert fit2 == pytest.approx(fit)


def test_an_error_unrelated_to_the_branch_is_left():
    w = _steps()
    cols = UnmodeledResonance.basis(w, 2000.0, 0.02, DT)
    resid = np.random.default_rng(2).normal(0.0, 0.01, w.size)   # white: no ring in it
    fixed, fit = branch_ratios(resid, cols, 0.0)
    assert fixed == pytest.approx(1.0)
    assert 0.97 < fit <= 1.0
