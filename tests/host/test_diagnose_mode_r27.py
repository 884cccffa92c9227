"""Round 27, the mode nested against a broad roll-off of G above its band: where the base's G is too large above
the band it was identified in, the deficit is broad and the mode's ring narrow; the mode's test nuisance
(:func:`piezoctl.ident.terms.rolloff_corrections`) takes the first and leaves the second."""

from types import SimpleNamespace

import numpy as np

from piezoctl.dsp import lowpass, mode_filter, filt
from piezoctl.ident import terms as T

DT = 1e-4          # [s] 10 kHz sampling
EDGE = 600.0       # [Hz] the band the base identified its dynamics in


def _ydyn(seed=0, n=20000):
    """A model output driven by steps and noise-like motion (rich above the edge) [um]."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-5.0, 5.0, n // 200), 200) + 0.3 * rng.standard_normal(n)
    return lowpass(u, 1500.0, DT)


def _ctx(ys, cal_band=300.0, dyn_band=EDGE):
    sigs = [SimpleNamespace(ydyn=y, dt=DT) for y in ys]
    valid = [np.arange(y.size) >= 500 for y in ys]
    return SimpleNamespace(signals=sigs, valid=valid, cal_band_hz=cal_band, dynamics_band_hz=dyn_band)


def _unexplained(X, e):
    """Share of ``e``'s energy the least-squares fit on the columns ``X`` leaves."""
    c, *_ = np.linalg.lstsq(X, e, rcond=None)
    return float(np.sum((e - X @ c) ** 2) / np.sum(e ** 2))


def test_a_first_order_rolloff_of_g_lies_in_the_columns():
    """The stage's response is the model's times 1 / (1 + s / w_e) (the base's G too large above the edge): the
    residual is taken whole, with gain -1 on the first column."""
    y = _ydyn()
    ctx = _ctx([y])
    X = T.rolloff_corrections(ctx, EDGE)
    e = (lowpass(y, EDGE, DT) - y)[ctx.valid[0]]
    c, *_ = np.linalg.lstsq(X, e, rcond=None)
    assert X.shape == (int(ctx.valid[0].sum()), 2)
    assert abs(c[0] + 1.0) < 1e-6 and abs(c[1]) < 1e-6
    assert _unexplained(X, e) < 1e-10


def test_a_second_order_rolloff_needs_the_second_column():
    """A deficit of two poles at the edge, ``L^2 - 1 = -2 HP + HP^2``, lies in the two columns exactly; the first
    column alone leaves a part of it (the second is a steeper roll-off, not a copy of the first)."""
    y = _ydyn(1)
    ctx = _ctx([y])
    X = T.rolloff_corrections(ctx, EDGE)
    e = (lowpass(lowpass(y, EDGE, DT), EDGE, DT) - y)[ctx.valid[0]]
    c, *_ = np.linalg.lstsq(X, e, rcond=None)
    assert _unexplained(X, e) < 1e-10 and abs(c[0] + 2.0) < 1e-6 and abs(c[1] - 1.0) < 1e-6
    assert _unexplained(X[:, :1], e) > 0.01


def test_a_narrow_ring_is_left_to_the_mode():
    """A mode's branch r (M(y) - y) at 2 kHz (damping 0.01) is narrow: the broad columns take little of it, so
    the mode nested against them keeps its ring."""
    y = _ydyn(2)
    ctx = _ctx([y])
    bm, am = mode_filter(2000.0, 0.01, DT)
    e = (0.05 * (filt(bm, am, y) - y))[ctx.valid[0]]
    assert _unexplained(T.rolloff_corrections(ctx, EDGE), e) > 0.5


def test_the_mode_states_its_test_nuisance_at_the_higher_band():
    """The mode's test nuisance is the roll-off at the higher of the calibration's band and the base's dynamics
    band, on every recording's settled samples; none without a band."""
    ys = [_ydyn(3, 8000), _ydyn(4, 6000)]
    term = T.TERMS["unmodeled_resonance"]
    ctx = _ctx(ys, cal_band=300.0, dyn_band=EDGE)
    N = term.test_nuisance(ctx)
    assert np.allclose(N, T.rolloff_corrections(ctx, EDGE))
    assert N.shape[0] == sum(int(v.sum()) for v in ctx.valid)
    assert np.allclose(term.test_nuisance(_ctx(ys, cal_band=900.0, dyn_band=EDGE)),
                       T.rolloff_corrections(ctx, 900.0))
    assert term.test_nuisance(_ctx(ys, cal_band=None, dyn_band=None)) is None


def test_the_mode_has_no_rolloff_after_a_first_term():
    """After a term is accepted (the folds' contexts carry its flexibility, the context of all data holds it in
    its model's ``terms``) the roll-off is not in the mode's test nor in its model's fit: measured in the first
    round only."""
    ys = [_ydyn(5, 6000)]
    term = T.TERMS["unmodeled_resonance"]
    first = _ctx(ys)
    first.base = {"terms": {}}
    assert term.test_nuisance(first) is not None
    folds = _ctx(ys)
    folds.accepted_flex = np.zeros((int(folds.valid[0].sum()), 1))
    assert term.test_nuisance(folds) is None
    everything = _ctx(ys)
    everything.base = {"terms": {"sensor_offset": {"offset_um": 0.3}}}
    assert term.test_nuisance(everything) is None
