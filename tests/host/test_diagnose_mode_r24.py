"""Round 24, the concealed mode beside a drive-side term: once a delay, an amplifier bandwidth or a slew limit is in
the model, the mode's block test reads the whole band only (the view above its edge does not count); in the first
round and beside any other term the two looks of round 23 stay."""

from types import SimpleNamespace

import numpy as np

from piezoctl.diagnose import select, significance as sg
from piezoctl.ident.terms import TERMS

EDGE = 1205.0 / np.sqrt(2.0)   # [Hz]
P_MAX = sg.ALPHA / 11


def _whole(p_above, dbic_above=-1e4):
    return {"above_hz": EDGE, "fold_ratios": [0.96, 0.97], "credited_ratio": 0.99, "p_above": p_above,
            "dbic_above": dbic_above, "share_above": 0.86}


def _further(x):
    return x < select.FURTHER_RATIO_MAX


def test_beside_a_drive_side_term_the_above_edge_p_alone_does_not_pass():
    """s131-007's figures (a delay accepted, the stage's first mode offered second): p 2.9e-2 on the whole band,
    1.2e-9 above the edge, dBIC -27. Round 23's two looks pass it; beside a drive-side term it is refused, and the
    record keeps what the two looks said."""
    w = _whole(1.2e-9)
    assert select._linearized_gates([0.44, 0.47], 2.9e-2, -27.0, dict(w), P_MAX, _further, False)
    assert not select._linearized_gates([0.44, 0.47], 2.9e-2, -27.0, w, P_MAX, _further, False, above_p=False)
    assert w["p_gate"] == 2.9e-2 and w["p_gate_above"] == 2 * 1.2e-9 and w["p_above_counted"] is False


def test_beside_a_drive_side_term_the_whole_band_p_still_passes():
    """Not stricter than round 22's gate there: a whole-band p below the level passes at the level, not at half."""
    w = _whole(0.5)
    assert select._linearized_gates([0.6, 0.6], 0.9 * P_MAX, -30.0, w, P_MAX, _further, False, above_p=False)
    assert w["p_gate"] == 0.9 * P_MAX
    assert not select._linearized_gates([0.6, 0.6], 1.1 * P_MAX, -30.0, _whole(1e-12), P_MAX, _further, False,
                                        above_p=False)


def test_the_first_round_keeps_both_looks():
    """On the base (no term yet) the view above the edge counts as in round 23 (s129-052: whole band 1.3e-3,
    above 9.1e-6)."""
    w = _whole(9.1e-6)
    assert select._linearized_gates([0.69, 0.64], 1.3e-3, -2121.0, w, sg.ALPHA / 12,
                                    lambda x: x <= sg.RATIO_MAX, True)
    assert w["p_gate"] == 2 * 9.1e-6 and w["p_above_counted"] is True


def test_beside_drive_reads_the_accepted_terms_group():
    """Only the drive-side group (delay, bandwidth, slew limit) switches the view off; an offset or a creep term
    acts below the mode's band, where the view above the edge is what separates the ring from it."""
    acc = lambda *names: [SimpleNamespace(term=TERMS[n]) for n in names]   # noqa: E731
    assert not select._beside_drive([])
    for n in ("delay", "amplifier_bandwidth", "amplifier_slew_limit"):
        assert select._beside_drive(acc(n)), n
        assert select._beside_drive(acc("sensor_offset", n)), n
    for n in ("sensor_offset", "creep", "thermal_drift", "cross_coupling", "rate_dependent_hysteresis"):
        assert not select._beside_drive(acc(n)), n
