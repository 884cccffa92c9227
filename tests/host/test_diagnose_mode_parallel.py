"""The concealed mode is a branch beside the identified dynamics (round 17): a stage's mechanics are a sum of modes
on one actuator, so a mode the calibration did not excite adds ``r (M(w) - w)`` on G's input ``w``, not a filter on
G's output. Above the stage's main mode G has rolled off, and the older series form cannot take such a mode."""

from types import SimpleNamespace

import numpy as np

from piezoctl.dsp import filt, mode_filter
from piezoctl.ident.terms import TERMS

DT = 1e-4
MAIN = (300.0, 0.08)      # the identified main mode [Hz, damping]
HIDDEN = (1000.0, 0.02)   # the concealed one
R = 0.08                  # its residue (a fraction of the static gain)


def _drive(seed=1):
    """Steps [um] (the reveal's fast edges): they ring every mode."""
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-5, 5, 40), 1000)


def _stage(h, r=R):
    """The base's G (the main mode, unit static gain) and the true stage: the same plus r (M_hidden(h) - h)."""
    y_base = filt(*mode_filter(*MAIN, DT), h)
    y_true = y_base + r * (filt(*mode_filter(*HIDDEN, DT), h) - h)
    return y_base, y_true


def _ratio(X, e):
    coef = np.linalg.lstsq(X, e, rcond=None)[0]
    return float(np.sqrt(np.sum((e - X @ coef) ** 2) / np.sum(e ** 2))), coef


def test_the_parallel_mode_takes_the_residual_the_series_form_cannot():
    h = _drive()
    y_base, y_true = _stage(h)
    e = y_true - y_base
    term = TERMS["unmodeled_resonance"]
    s = SimpleNamespace(h=h, ydyn=y_base, dt=DT)
    ratio, coef = _ratio(term.columns(None, s, HIDDEN), e)
    assert ratio < 0.05                       # the branch on G's input is the stage's own form
    assert abs(coef.sum() - R) < 0.1 * R      # and its gain is the mode's residue
    series, _ = _ratio(term.basis(y_base, *HIDDEN, DT), e)   # rounds 12-16: the mode on G's output
    assert series > 0.5


def test_the_simulation_is_the_regressor_and_old_models_stay_in_series():
    h = _drive(2)
    y_base, _ = _stage(h)
    term = TERMS["unmodeled_resonance"]
    s = SimpleNamespace(h=h, ydyn=y_base, dt=DT)
    coef = [0.05, 0.02]
    par = term.model_params(None, HIDDEN, coef)
    assert par["input"] == "dynamics_input"
    st = SimpleNamespace(y=y_base.copy(), w=h, dt=DT)
    term.apply(par, st)
    assert np.allclose(st.y - y_base, term.columns(None, s, HIDDEN) @ coef, atol=1e-12)
    old = {k: v for k, v in par.items() if k != "input"}   # a refined model written before round 17
    st = SimpleNamespace(y=y_base.copy(), w=h, dt=DT)
    term.apply(old, st)
    assert np.allclose(st.y - y_base, term.basis(y_base, *HIDDEN, DT) @ coef, atol=1e-12)
    assert not np.allclose(st.y - y_base, term.columns(None, s, HIDDEN) @ coef, atol=1e-3)


def test_the_mode_is_sized_above_its_own_band_or_the_calibrations():
    """Round 17: below f / sqrt(2) the branch moves less than its static share; the edge is the higher of that and
    the calibration's band, from the lower of the folds' frequencies."""
    term = TERMS["unmodeled_resonance"]
    ctx = SimpleNamespace(cal_band_hz=350.0)
    assert abs(term.acts_above_hz(ctx, [(1030.0, 0.05), (1000.0, 0.02)]) - 1000.0 / np.sqrt(2.0)) < 1e-9
    assert term.acts_above_hz(ctx, [(400.0, 0.05), (410.0, 0.05)]) == 350.0
    x = np.array([0.5, 0.7, 0.72, 0.9])   # |M(f') - 1| against 1 around f / sqrt(2), the vocabulary's dampings
    for z in term.DAMPINGS:
        m1 = np.abs((x ** 2 - 2j * z * x) / (1 - x ** 2 + 2j * z * x))
        assert np.all((m1 < 1) == (x < 1 / np.sqrt(2)))
    assert all(TERMS[n].acts_above_hz(ctx, [None]) is None for n in TERMS if n != "unmodeled_resonance")
