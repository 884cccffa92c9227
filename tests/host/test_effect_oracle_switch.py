"""bench.effect_oracle.switch_off (round 24: a concealed mode too): the stage with the effect off is the case's own
reference, ``Case.without_effects``, for a single-effect case."""

import copy

import pytest

from piezoctl.bench.effect_oracle import switch_off
from piezoctl.foreign.cases import draw_case
from piezoctl.foreign.stage import FS_HZ


def test_a_concealed_mode_is_removed_and_its_residue_given_back():
    case = draw_case(131, 6, ("unmodeled_resonance",), scale=0.5)
    st = copy.deepcopy(case.stage)
    n, total = len(st.modes), sum(m.r for m in st.modes)
    switch_off(st, "unmodeled_resonance")
    assert len(st.modes) == n - 1
    assert sum(m.r for m in st.modes) == pytest.approx(total)   # the static gain is kept
    ref = case.without_effects()
    assert [x for m in st.modes for x in (m.f_hz, m.zeta, m.r)] == pytest.approx(
        [x for m in ref.modes for x in (m.f_hz, m.zeta, m.r)])
    assert len(case.stage.modes) == n   # the case's own stage is untouched


def test_creep_and_coupling_still_switch_off_and_others_are_refused():
    case = draw_case(131, 0, ("creep",), scale=0.5)
    st = copy.deepcopy(case.stage)
    assert st.creep is not None
    switch_off(st, "creep")
    assert st.creep is None
    with pytest.raises(ValueError):
        switch_off(copy.deepcopy(case.stage), "saturation")


def test_the_asymmetry_switches_off_and_the_rails_stay():
    # round 26: the extra beyond the knee is the effect; the amplifier's rails are the stage's own
    case = draw_case(131, 13, ("asymmetric_hysteresis",), scale=0.5)
    st = copy.deepcopy(case.stage)
    assert st.asym is not None
    rails = tuple(st.rails_v)
    switch_off(st, "asymmetric_hysteresis")
    assert st.asym is None
    assert tuple(st.rails_v) == rails
    assert case.stage.asym is not None   # the case's own stage is untouched


def test_a_drift_switches_off_and_the_calibration_it_never_reached_is_unchanged():
    # round 26: the drift's oracle; the drift begins after the calibration, so its base is the kept one
    case = draw_case(131, 1, ("thermal_drift",), scale=0.5)
    st = copy.deepcopy(case.stage)
    assert st.drift is not None
    switch_off(st, "thermal_drift")
    assert st.drift is None and case.stage.drift is not None
    t_end = max(r.t_session + r.u.size / FS_HZ for r in case.calibration)
    assert case.stage.drift.t_on_s >= t_end - 1e-9


@pytest.mark.parametrize("effect,index", [("delay", 7), ("amplifier_bandwidth", 10), ("sensor_offset", 2),
                                          ("rate_dependent_hysteresis", 4)])
def test_drive_side_sensor_and_rate_effects_switch_off_as_the_case_s_reference(effect, index):
    """Round 26: the stage with the effect off equals ``Case.without_effects`` in what the effect sets, and the
    case's own stage still has it."""
    case = draw_case(131, index, (effect,), scale=0.5)
    st = copy.deepcopy(case.stage)
    switch_off(st, effect)
    ref = case.without_effects()
    assert st.delay_samples == ref.delay_samples == 1
    assert st.amp_fc_hz is None and st.rate is None
    assert st.sensor.offset_by_session == ref.sensor.offset_by_session
    own = case.stage
    assert {"delay": own.delay_samples > 1, "amplifier_bandwidth": own.amp_fc_hz is not None,
            "sensor_offset": len(own.sensor.offset_by_session) > 1,
            "rate_dependent_hysteresis": own.rate is not None}[effect]


def test_a_sensor_curve_switches_off_to_the_calibration_s_curve_on_every_session():
    """Round 28: the sensor curve's oracle; the calibration's session keeps its own curve, so its base is the kept
    one, and the reveal session reads through that same curve once the effect is off."""
    case = draw_case(131, 11, ("sensor_nonlinearity",), scale=0.5)
    own = case.stage.sensor.nl_by_session
    assert len(own) > 1 and own[1] != own[0]
    st = copy.deepcopy(case.stage)
    switch_off(st, "sensor_nonlinearity")
    assert st.sensor.nl_by_session == {0: own[0]}
    assert st.sensor.nl_by_session == case.without_effects().sensor.nl_by_session
    assert case.stage.sensor.nl_by_session[1] == own[1]   # the case's own stage is untouched
