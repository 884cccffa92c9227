"""Foreign stage simulator (host/piezoctl/foreign, docs/foreign-stage.md): laws are hysteretic,
rate-independent and (where they should) have return-point memory; cases are deterministic;
every concealed effect changes the reveal and is switched off when off; files load."""

from __future__ import annotations

import collections

import numpy as np
import pytest

from piezoctl.foreign import hysteresis as hy
from piezoctl.foreign.cases import EFFECTS, case_plan, draw_case, write_case
from piezoctl.io.recording import load_recording

LAW_NAMES = list(hy.LAWS)


def _law(name, seed=7):
    return hy.LAWS[name].draw(np.random.default_rng(seed))


def _path(vertices, n):
    """Piecewise-linear path through the vertices, n samples per segment (vertices included)."""
    out = [np.array([vertices[0]])]
    for a, b in zip(vertices[:-1], vertices[1:]):
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


@pytest.mark.parametrize("name", LAW_NAMES)
def test_law_is_hysteretic_and_normalized(name):
    law = _law(name)
    n = 1000
    up = np.linspace(-1, 1, n)
    h = law(np.concatenate((up, up[::-1], up, up[::-1])))
    asc, desc = h[2 * n:3 * n], h[3 * n:][::-1]
    area = np.trapezoid(desc - asc, up)
    assert area > 0.02                      # counter-clockwise loop of real width
    assert 0.08 <= hy.loop_width(law) <= 0.40
    assert h[2 * n:].min() == pytest.approx(-1, abs=1e-6) and h[2 * n:].max() == pytest.approx(1, abs=1e-6)


@pytest.mark.parametrize("name", [n for n in LAW_NAMES if hy.LAWS[n].return_point_memory])
def test_return_point_memory(name):
    law = _law(name, seed=11)
    direct = law(_path([-1.0, 0.2, 0.7], 400))
    looped = law(_path([-1.0, 0.2, -0.3, 0.2, 0.7], 400))
    assert looped[-1] == pytest.approx(direct[-1], abs=1e-9)
    # the minor loop closes: back at 0.2 the output is where it left
    assert looped[1200] == pytest.approx(looped[400], abs=1e-9)
    # and the minor loop is a loop, not a retrace: at v = -0.05 down and up differ
    assert abs(looped[1000] - looped[600]) > 1e-4


def test_duhem_laws_have_no_exact_return_point_memory():
    # the check above can fail: Coleman-Hodgdon's minor loop does not close exactly
    law = _law("coleman_hodgdon", seed=3)
    looped = law(_path([-1.0, 0.2, -0.6, 0.2], 400))
    assert abs(looped[1200] - looped[400]) > 1e-6


@pytest.mark.parametrize("name", LAW_NAMES)
def test_rate_independent(name):
    law = _law(name, seed=5)
    verts = [-1.0, 0.8, -0.4, 0.5, -0.1, 1.2, -1.3]
    slow = law(_path(verts, 2000))
    fast = law(_path(verts, 200))
    assert np.max(np.abs(slow[::10] - fast)) < 1e-6


def test_rate_dependent_option_widens_the_loop():
    law = _law("generalized_pi", seed=2)
    v = np.concatenate((np.linspace(-1, 1, 500), np.linspace(1, -1, 500)))
    plain = law(v)
    wide = law(v, width=np.full(v.size, 1.5))
    assert np.max(np.abs(plain[:500] - plain[500:][::-1])) < np.max(np.abs(wide[:500] - wide[500:][::-1]))
    with pytest.raises(ValueError):
        _law("preisach")(v, width=np.ones(v.size))


def test_case_plan_is_balanced():
    plan = case_plan(60)
    count = collections.Counter(p[0] if p else "none" for p in plan)
    assert count["none"] == 12 and all(count[e] == 4 for e in EFFECTS)
    assert len(case_plan(8, multi=True)) == 8


def test_cases_are_deterministic_per_seed():
    a = draw_case(3, 1, ("delay",), scale=0.1)
    b = draw_case(3, 1, ("delay",), scale=0.1)
    c = draw_case(4, 1, ("delay",), scale=0.1)
    assert a.info == b.info and all(np.array_equal(x.u, y.u) for x, y in zip(a.reveal, b.reveal))
    r = a.reveal[0]
    ya = a.stage.run(r.u, r.u2, r.t_session, r.session, r.pre_s, np.random.default_rng(0))
    yb = b.stage.run(r.u, r.u2, r.t_session, r.session, r.pre_s, np.random.default_rng(0))
    assert np.array_equal(ya, yb)
    assert a.info["delay_ms"] != c.info["delay_ms"]


def _x(stage, r, sensor):
    reps = int(np.ceil(r.warmup_s * 1e4 / r.u.size)) + 1 if r.warmup_s else 1
    u2 = None if r.u2 is None else np.tile(r.u2, reps)
    x = stage.displacement(np.tile(r.u, reps), u2, r.t_session, r.pre_s)[-r.u.size:]
    if sensor:
        s = stage.sensor
        s_noise, s.noise_um = s.noise_um, 0.0
        x = s.read(x, r.session, stage.stroke_um / 2, stage.stroke_um / 2, np.random.default_rng(0))
        s.noise_um = s_noise
    return x


def _misfit(a, b):
    """RMS of a - (c0 + c1 b + c2 db/dt): what gain, offset and a small lag cannot explain [um]."""
    X = np.column_stack([np.ones(b.size), b, np.gradient(b)])
    return float(np.sqrt(np.mean((a - X @ np.linalg.lstsq(X, a, rcond=None)[0]) ** 2)))


@pytest.mark.parametrize("effect", EFFECTS)
def test_effect_is_concealed_in_calibration_and_shows_in_reveal(effect):
    case = draw_case(1, 500 + EFFECTS.index(effect), (effect,), scale=0.2)
    off = case.without_effects()
    sensor = effect.startswith("sensor")
    k0 = 2000
    cal = max(_misfit(_x(case.stage, r, sensor)[k0:], _x(off, r, sensor)[k0:]) for r in case.calibration)
    rev_diff = [np.abs(_x(case.stage, r, sensor)[k0:] - _x(off, r, sensor)[k0:]) for r in case.reveal]
    rev = max(float(np.sqrt(np.mean(d ** 2))) for d in rev_diff)
    noise = case.stage.sensor.noise_um
    assert rev > 3 * noise, (effect, rev, noise)
    assert rev > 1.5 * cal, (effect, rev, cal)


def test_off_is_off():
    case = draw_case(1, 7, (), scale=0.1)
    off = case.without_effects()
    for r in case.calibration + case.reveal:
        assert np.array_equal(_x(case.stage, r, True), _x(off, r, True))
    assert case.stage.creep is None and case.stage.drift is None and case.stage.coupling is None


def test_files_load(tmp_path):
    case = draw_case(2, 3, ("cross_coupling",), scale=0.05)
    files = write_case(case, str(tmp_path / case.case_id))
    assert files["truth"] == ["cross_coupling"]
    for p in files["calibration"] + files["recordings"]:
        rec = load_recording(p)
        assert rec.sample_rate_hz == 10000 and rec.u2 is not None
        assert np.all(np.isfinite(rec.y)) and len(rec) > 1000
    moving = [np.ptp(load_recording(p).u2) for p in files["recordings"]]
    held = [np.ptp(load_recording(p).u2) for p in files["calibration"]]
    assert max(held) == 0 and max(moving) > 10
