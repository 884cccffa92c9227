"""Round 20: a delay told from the amplifier's pole by the magnitude (``signature.delay_or_pole``) and its use in the
selection when both pass (``select._delay_or_pole``, ``select._separate``). Synthetic model outputs x and
measurements y = (a known shape applied to x) + noise, the stage's one-sample latency in front of every pole."""

import types

import numpy as np
from scipy import signal as sps

from piezoctl.diagnose import select as S
from piezoctl.diagnose import signature as sig
from piezoctl.ident.terms import TERMS

DT = 1e-4          # 10 kHz
F_BAND = 20.0      # [Hz] the band "the calibration identified"
N = 60_000         # 6 s per recording


def _drive(seed, f_cut):
    """A model output [um]: white noise low-passed at ``f_cut`` [Hz] plus a slow sine."""
    rng = np.random.default_rng(seed)
    b, a = sps.butter(2, f_cut, fs=1.0 / DT)
    return 2.0 * np.sin(2 * np.pi * 2.0 * np.arange(N) * DT) + sps.lfilter(b, a, rng.standard_normal(N))


def _delay(x, d):
    return np.concatenate([np.full(d, x[0]), x[:-d]])


def _pole(x, fc):
    b, a = sps.butter(1, fc, fs=1.0 / DT)
    return sps.lfilter(b, a, x)


def _recordings(shape, f_cut):
    xs = [_drive(s, f_cut) for s in (1, 2)]
    ys = [shape(x) + 0.02 * np.random.default_rng(s + 100).standard_normal(N) for x, s in zip(xs, (1, 2))]
    return xs, ys


def _verdict(shape, f_cut, f_drive, f_band=F_BAND):
    xs, ys = _recordings(shape, f_cut)
    return sig.delay_or_pole(sig.transfer(xs, ys, DT), DT, f_band, f_drive)


def test_a_delay_is_told_from_a_pole_where_the_drive_reaches_the_pole_s_fall():
    g = _verdict(lambda x: _delay(x, 8), 300.0, 400.0)          # 0.8 ms, drive to 400 Hz
    assert g["verdict"] == "delay", g["reason"]
    assert abs(g["figures"]["delay_s"] - 8 * DT) <= 0.5 * DT
    assert g["figures"]["p_delay"] < sig.ALPHA


def test_a_pole_behind_the_loop_s_latency_is_told_from_a_delay():
    g = _verdict(lambda x: _delay(_pole(x, 250.0), 1), 300.0, 400.0)   # magnitude 0.53 at 400 Hz
    assert g["verdict"] == "amplifier_bandwidth", g["reason"]
    assert 200.0 < g["figures"]["fc_hz"] < 310.0
    assert g["figures"]["pole_drop_at_top"] > 0.3


def test_the_pole_is_fitted_behind_the_loop_s_latency():
    # two samples of latency before a 300 Hz pole (s124-056: 81 degrees of lag at 540 Hz where its pole gives 56):
    # the pole alone cannot follow the phase, and the delay's free gain takes the fall; with the latency the pole
    # fits within the noise
    g = _verdict(lambda x: _delay(_pole(x, 300.0), 2), 450.0, 550.0)
    assert g["verdict"] == "amplifier_bandwidth", g["reason"]
    assert g["figures"]["pole_latency_s"] > 0.5 * DT
    assert 270.0 < g["figures"]["fc_hz"] < 330.0


def test_below_the_pole_s_fall_the_two_are_not_told_apart():
    # a 400 Hz pole seen to 60 Hz only: its magnitude is down 2 % there, within what a delay's gain takes
    g = _verdict(lambda x: _delay(_pole(x, 400.0), 1), 30.0, 60.0)
    assert g["verdict"] is None, g["reason"]
    assert "do not tell" in g["reason"]
    g = _verdict(lambda x: _delay(x, 4), 30.0, 60.0)
    assert g["verdict"] is None, g["reason"]


def test_a_drive_inside_the_identified_band_is_read_up_to_the_drive_s_band_only():
    # the drive moves to 60 Hz inside a 500 Hz band; the informative bins above it (a broadband drive's tail
    # here, the stage's modes rung by harmonics on a stage) do not decide between the two
    g = _verdict(lambda x: _delay(_pole(x, 250.0), 1), 300.0, 60.0, f_band=500.0)
    assert g["verdict"] is None, g["reason"]
    assert g["figures"]["f_max_hz"] <= 60.0
    assert _verdict(lambda x: _delay(_pole(x, 250.0), 1), 300.0, None, f_band=500.0)["verdict"] == "amplifier_bandwidth"


def test_bins_with_the_magnitude_above_one_are_kept_against_the_pole():
    # a delay whose magnitude lies a little above 1 (G's continuation): the shape tests' below_unity would drop
    # those bins; here they are the evidence that the magnitude does not fall
    g = _verdict(lambda x: 1.05 * _delay(x, 8), 300.0, 400.0)
    assert g["verdict"] == "delay", g["reason"]
    assert g["figures"]["bins"] >= 30


def _cand(name):
    return S.Candidate(term=TERMS[name], ratio=0.6, fold_ratios=[0.6, 0.6], nrmse_before=0.02, nrmse_after=0.012,
                       t=5.0, p=1e-9, n_active=40, p_max=1e-3, dbic=-50.0, n_eff=500.0, significant=True,
                       setting=[8, 8], coef=[None, None], credited=0.6)


def _ctx(shape):
    xs, ys = _recordings(shape, 300.0)
    sigs = [types.SimpleNamespace(yb=x, y=y, u=x) for x, y in zip(xs, ys)]
    return types.SimpleNamespace(signals=sigs, valid=[np.ones(N, bool)] * 2, dt=DT)


def test_selection_refuses_the_shape_the_other_fits_better_and_keeps_the_order():
    ctx = _ctx(lambda x: _delay(_pole(x, 250.0), 1))
    d, b, r = _cand("delay"), _cand("amplifier_bandwidth"), _cand("amplifier_slew_limit")
    evals = [d, r, b]
    S._delay_or_pole(evals, ctx, F_BAND, lambda *a: None)
    assert evals == [d, r, b] and r.veto is None   # the slew limit the discrimination put before the pole stays so
    assert d.veto and d.veto.startswith("its shape is the amplifier_bandwidth's")
    assert b.veto is None and b.delay_or_pole["other"] == "delay"
    assert b.delay_or_pole["verdict"] == "amplifier_bandwidth"


def test_selection_names_the_pair_inseparable_where_the_data_cannot_tell_them(monkeypatch):
    xs, ys = _recordings(lambda x: _delay(_pole(x, 400.0), 1), 30.0)
    ctx = types.SimpleNamespace(signals=[types.SimpleNamespace(yb=x, y=y, u=x) for x, y in zip(xs, ys)],
                                valid=[np.ones(N, bool)] * 2, dt=DT)
    d, b = _cand("delay"), _cand("amplifier_bandwidth")
    evals = [d, b]
    S._delay_or_pole(evals, ctx, F_BAND, lambda *a: None)
    assert evals == [d, b] and d.veto is None and b.veto is None
    # the named one carries the other as an alternative the data cannot tell from it
    monkeypatch.setattr(S, "separate", lambda *a, **k: [])
    fctx = [types.SimpleNamespace(valid=[np.ones(4, bool)], dt=DT, design_cache={})] * 2
    S._separate(d, evals, fctx, [np.zeros(4)] * 2, np.zeros(4, int), np.zeros(4, int), 10, lambda *a: None)
    assert [(r["name"], r["verdict"]) for r in d.separation] == [("amplifier_bandwidth", "inseparable")]
    assert "do not tell" in d.separation[0]["reason"]


def test_selection_leaves_the_order_when_only_one_of_the_pair_passes():
    ctx = _ctx(lambda x: _delay(_pole(x, 250.0), 1))
    d, b = _cand("delay"), _cand("amplifier_bandwidth")
    b.significant = False
    evals = [d, b]
    S._delay_or_pole(evals, ctx, F_BAND, lambda *a: None)
    assert evals == [d, b] and d.veto is None and d.delay_or_pole is None
