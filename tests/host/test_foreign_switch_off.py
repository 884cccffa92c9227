"""foreign.cases.switch_off: one per-effect switch; ``Case.without_effects`` is every effect's switch, so a
single-effect case switched off for its own effect alone is the case's reference, for every effect."""

import copy

import numpy as np
import pytest

from piezoctl.foreign.cases import EFFECTS, case_plan, draw_case, switch_off

_PLAN = case_plan(60)


def _reading(stage, rec):
    st = copy.deepcopy(stage)
    st.sensor.noise_um, st.sensor.lsb_um = 0.0, 1e-9
    x = st.displacement(rec.u, rec.u2, rec.t_session, rec.pre_s)
    return st.sensor.read(x, rec.session, 0.5 * st.stroke_um, 0.5 * st.stroke_um, np.random.default_rng(0))


@pytest.mark.parametrize("effect", EFFECTS)
def test_one_effect_switched_off_is_the_cases_reference(effect):
    index = next(i for i, t in enumerate(_PLAN) if t == (effect,))
    case = draw_case(131, index, (effect,), scale=0.5)
    st = copy.deepcopy(case.stage)
    switch_off(st, effect)
    ref = case.without_effects()
    rec = case.reveal[0]
    with_effect, off, want = (_reading(s, rec) for s in (case.stage, st, ref))
    assert np.array_equal(off, want)
    # the switch acted: the effect changes the reveal's reading (the offset's and the curve's only on the
    # sessions after the calibration's, the drift's only after its start: every reveal here reaches them)
    assert np.max(np.abs(with_effect - off)) > 1e-6


def test_a_null_stage_keeps_its_modes_and_an_unknown_effect_is_refused():
    index = _PLAN.index(())
    case = draw_case(131, index, (), scale=0.5)
    ref = case.without_effects()
    assert len(ref.modes) == len(case.stage.modes)   # no concealed mode: every mode is the stage's own
    with pytest.raises(ValueError):
        switch_off(copy.deepcopy(case.stage), "hum")
