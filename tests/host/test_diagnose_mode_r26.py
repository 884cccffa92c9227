"""Round 26, where the mode is offered: a mode of the stage adds response (a local peak of the measured-over-model
magnitude |T|); where the base's dynamics are many times too large above its band, |T - 1| is a plateau near 1
and its largest ripple is no mode: without any |T| peak above the band nothing is offered (development null
s136-009: a false mode at 4820 Hz)."""

import numpy as np

from piezoctl.diagnose import signature as sig

F = np.arange(10.0, 5000.0, 10.0)   # [Hz] bins of a 10 kHz recording
VAR = 1e-6                          # variance of each of Re T, Im T (a long, coherent estimate)
BAND = 600.0                        # [Hz] the band the base identified its dynamics in


def _tr(T):
    return sig.Transfer(f=F, T=np.asarray(T, complex), g2=np.full(F.size, 0.99), var=np.full(F.size, VAR),
                        n_d=200, df=10.0, segments=200)


def _overshoot():
    """The stage's response over the model's: 1 in the band, falling to 0.05 above it (the base's G too large
    there), with a phase ripple at 4680 Hz that makes |T - 1| peak there and leaves |T| smooth."""
    c = 1.0 / (1.0 + (F / 700.0) ** 2) + 0.05
    phase = 0.6 + 2.5 * np.exp(-0.5 * ((F - 4680.0) / 60.0) ** 2)
    return c * np.exp(1j * phase * (F / 5000.0))


def _mode(f0=3000.0, zeta=0.02, r=0.03):
    """A missing mode's factor ``1 + r (M - 1)`` (unit static gain, residue ``r``)."""
    return 1.0 + r * (sig.mode_response(F, f0, zeta) - 1.0)


def test_the_overshoot_plateau_offers_no_mode():
    """s136-009's shape: the |T - 1| peak is significant where |T| is far below 1, and |T| has no peak of its own:
    nothing is offered (the |T - 1| peak alone would offer 4680 Hz), and a mode there fails its check."""
    tr = _tr(_overshoot())
    assert not sig.check_mode(tr, 1.0, BAND, 4680.0, 0.05)["passed"]
    i, significant = sig._deviation_peak(tr, f_above=BAND)
    assert significant and abs(tr.f[i] - 4680.0) <= 30.0 and abs(tr.T[i]) < 0.5
    assert sig.transfer_peak(tr, f_above=BAND)[1] is False
    assert sig.mode_frequencies(tr, f_min=BAND) == []


def test_a_mode_under_the_overshoot_keeps_the_offer():
    """s134-006's shape: a 3000 Hz mode under a base G many times too large; |T| peaks at the mode, so the stage
    shows an excess and the |T - 1| peak stays offered (round 26 only withdraws an offer where |T| shows none)."""
    tr = _tr(_overshoot() * _mode())
    i, significant = sig._deviation_peak(tr, f_above=BAND)
    assert significant and abs(tr.T[i]) < 0.5
    assert sig._excess_peak(tr, f_above=BAND) is not None
    assert sig.transfer_peak(tr, f_above=BAND) == (i, True)
    assert sig.mode_frequencies(tr, f_min=BAND) == [float(tr.f[i])]


def test_a_mode_above_a_faithful_continuation_keeps_the_deviation_peak():
    """Where the measurement exceeds the model at the |T - 1| peak (|T| > 1: the usual mode), the offer is the
    |T - 1| peak, as before round 26."""
    tr = _tr(_mode(f0=2500.0, zeta=0.03, r=-0.06))
    i, significant = sig._deviation_peak(tr, f_above=BAND)
    assert significant and abs(tr.T[i]) > 1.0
    assert sig.transfer_peak(tr, f_above=BAND) == (i, True)


def test_excess_peak_needs_a_significant_prominence():
    """A |T| ripple within the estimate's spread is no peak; one well beyond it is."""
    small = np.full(F.size, 0.1, complex)
    small[200] += 0.5 * np.sqrt(VAR)
    assert sig._excess_peak(_tr(small), f_above=BAND) is None
    big = np.full(F.size, 0.1, complex)
    big[200] += 50 * np.sqrt(VAR)
    assert sig._excess_peak(_tr(big), f_above=BAND) == 200
