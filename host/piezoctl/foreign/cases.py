"""Randomized foreign benchmark cases for ``piezoctl diagnose`` (docs/foreign-stage.md).

A case is a random :class:`~piezoctl.foreign.stage.Stage` with zero, one or two concealed
effects, calibration recordings (what users record: decaying sines, FORC sweeps, random
walks, triangles, a small chirp) and reveal recordings designed so that the effect is
hidden in the calibration and shows in the reveal set. Every range used here is written in
docs/foreign-stage.md; they were fixed before any diagnosis ran on these cases.

Seeds 0..9 are for development; seeds >= 100 are held out (never looked at while tuning).
"""

from __future__ import annotations

import copy
import dataclasses
import os
import zlib

import numpy as np

from ..io.recording import save_recording
from . import signals as sg
from .hysteresis import LAWS, draw_law
from .stage import (FS_HZ, Asymmetry, Coupling, Creep, Drift, Mode, RateDependence, Sensor,
                    Stage)

__all__ = ["EFFECTS", "MULTI_PAIRS", "Rec", "Case", "switch_off", "case_plan", "draw_case", "write_case"]

EFFECTS = ("creep", "thermal_drift", "sensor_offset", "cross_coupling", "rate_dependent_hysteresis",
           "unmodeled_resonance", "delay", "amplifier_slew_limit", "amplifier_bandwidth",
           "sensor_nonlinearity", "saturation", "asymmetric_hysteresis")
# [V] the amplifier's own rails; a concealed saturation brings one of them in
AMP_RAILS_V = (-30.0, 160.0)
# Two-effect cases: pairs whose concealments are compatible.
MULTI_PAIRS = (("creep", "cross_coupling"), ("thermal_drift", "amplifier_slew_limit"),
               ("sensor_offset", "unmodeled_resonance"), ("sensor_nonlinearity", "delay"))
# Designs whose reveal stays inside the calibrated drive range: nulls use one of these.
IN_RANGE_DESIGNS = tuple(e for e in EFFECTS if e not in ("saturation", "asymmetric_hysteresis"))
SLOW_CAL = ("rate_dependent_hysteresis", "delay", "amplifier_slew_limit", "amplifier_bandwidth")


@dataclasses.dataclass
class Rec:
    """One recording to simulate: drive ``u`` [V], other axis ``u2`` [V] or None, session
    time of its start ``t_session`` [s], sensor ``session``, hold before it ``pre_s`` [s],
    and ``warmup_s`` [s] of the same periodic drive before it (not recorded)."""

    name: str
    u: np.ndarray
    u2: np.ndarray | None
    t_session: float
    session: int
    pre_s: float
    warmup_s: float = 0.0     # the same (periodic) drive ran this long before the recording [s]


@dataclasses.dataclass
class Case:
    """A benchmark case: the stage, its recordings and what is concealed."""

    case_id: str
    truth: tuple
    design: str
    stage: Stage
    calibration: list
    reveal: list
    info: dict

    def without_effects(self) -> Stage:
        """A copy of the stage with every concealed effect switched off (the same law,
        modes, amplifier and sensor otherwise): the reference an effect is measured against.
        Each effect is switched off by :func:`switch_off`; the last mode is only taken out when
        it is the concealed one (it is the stage's own otherwise)."""
        st = copy.deepcopy(self.stage)
        for effect in EFFECTS:
            if effect != "unmodeled_resonance" or effect in self.truth:
                switch_off(st, effect)
        return st


def switch_off(stage: Stage, effect: str) -> None:
    """Switch one concealed ``effect`` (one of :data:`EFFECTS`) off in ``stage``, in place.

    A stage without the effect is left as it is, except for ``unmodeled_resonance``: the last
    mode of ``stage.modes`` is removed and its residue given back to the first mode (the static
    gain stays), so call it only on a stage whose last mode is the concealed one. The delay goes
    back to the loop's own sample, the rails to the amplifier's own (:data:`AMP_RAILS_V`), the sensor's zero
    and curve to the calibration's session's on every session. Any other name raises
    ``ValueError``. One switch for :meth:`Case.without_effects` and ``bench.effect_oracle``.
    """
    if effect in _EFFECT_ATTR:
        setattr(stage, _EFFECT_ATTR[effect], None)
    elif effect == "delay":
        stage.delay_samples = 1
    elif effect == "saturation":
        stage.rails_v = AMP_RAILS_V
    elif effect == "unmodeled_resonance":
        res = stage.modes.pop()
        stage.modes[0].r += res.r
    elif effect == "sensor_offset":
        stage.sensor.offset_by_session = {0: stage.sensor.offset_by_session[0]}
    elif effect == "sensor_nonlinearity":
        stage.sensor.nl_by_session = {0: stage.sensor.nl_by_session[0]}
    else:
        raise ValueError(f"unknown effect {effect!r}")


# effects that are one optional part of the stage, absent when None
_EFFECT_ATTR = {"creep": "creep", "thermal_drift": "drift", "cross_coupling": "coupling",
                "rate_dependent_hysteresis": "rate", "asymmetric_hysteresis": "asym",
                "amplifier_slew_limit": "slew_v_per_s", "amplifier_bandwidth": "amp_fc_hz"}


def case_plan(n: int, multi: bool = False) -> list[tuple]:
    """Truths of the n cases of one seed.

    Single-effect plan: round(n / 5) nulls (truth ``()``) spread evenly, the other cases
    cycle through :data:`EFFECTS` in order (n = 60: 12 nulls and 4 of each effect).
    Two-effect plan: cycles through :data:`MULTI_PAIRS`.
    """
    if multi:
        return [MULTI_PAIRS[i % len(MULTI_PAIRS)] for i in range(n)]
    n_null = int(round(n / 5))
    null_at = set(np.round(np.linspace(0, n - 1, n_null + 2)[1:-1]).astype(int).tolist()) if n_null else set()
    while len(null_at) < n_null:
        null_at.add(max(set(range(n)) - null_at))
    out, k = [], 0
    for i in range(n):
        if i in null_at:
            out.append(())
        else:
            out.append((EFFECTS[k % len(EFFECTS)],))
            k += 1
    return out


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


def _draw_stage(rng, law_names, f1_min_hz=300.0):
    law = draw_law(rng, law_names[int(rng.integers(len(law_names)))])
    n_modes = int(rng.integers(1, 4))
    f = [_u(rng, max(300.0, f1_min_hz), max(2000.0, 1.2 * f1_min_hz))]
    for _ in range(n_modes - 1):
        f.append(f[-1] * _u(rng, 1.4, 2.5))
    f = [min(x, 4200.0) for x in f]
    res = [float(rng.choice([-1, 1]) * rng.uniform(0.02, 0.15)) for _ in f[1:]]
    modes = [Mode(f[0], _u(rng, 0.02, 0.15), 1.0 - sum(res))]
    modes += [Mode(fi, _u(rng, 0.02, 0.15), ri) for fi, ri in zip(f[1:], res)]
    stroke = _u(rng, 15, 100)
    bits = int(rng.choice([16, 18, 20]))
    eps0 = _u(rng, -0.002, 0.002)
    sensor = Sensor(gain=_u(rng, 0.98, 1.02), noise_um=_u(rng, 0.002, 0.010),
                    lsb_um=1.25 * stroke / 2 ** bits, offset_by_session={0: _u(rng, -0.5, 0.5)},
                    nl_by_session={0: eps0}, lam=_u(rng, 0.1, 0.3))
    return Stage(law=law, stroke_um=stroke, amp_gain=_u(rng, 0.95, 1.05), amp_offset_v=_u(rng, -1, 1),
                 rails_v=AMP_RAILS_V, modes=modes, sensor=sensor, delay_samples=1)


def draw_case(seed: int, index: int, truth: tuple, scale: float = 1.0, design: str | None = None) -> Case:
    """Draw case ``index`` of ``seed`` with the concealed effects ``truth`` (``()``: null).

    Parameters
    ----------
    seed, index : int
        The case's random stream is ``numpy.random.default_rng([seed, index])``.
    truth : tuple of str
        Concealed effects (names of :data:`EFFECTS`), empty for a null stage.
    scale : float
        Duration factor of every recording (1: 60 to 100 s of data per case).
    design : str, optional
        For a null: the effect design whose calibration and reveal recordings are used
        (default: drawn from the in-range designs).
    """
    rng = np.random.default_rng([seed, index])
    truth = tuple(truth)
    if not truth:
        design = design or IN_RANGE_DESIGNS[int(rng.integers(len(IN_RANGE_DESIGNS)))]
        designs = (design,)
    else:
        designs = truth
        design = "+".join(truth)
    info: dict = {}
    S = scale

    # ---- constraints from the designs
    lo, hi = _u(rng, 0, 10), _u(rng, 135, 150)          # calibrated drive range [V]
    cal_top = None                                      # top of the calibration chirp [Hz]
    rev_top = 400.0                                     # top frequency of the reveal drives [Hz]
    f1_min = 300.0
    laws = list(LAWS)
    eff = {}
    if "rate_dependent_hysteresis" in designs:
        eff["rate"] = RateDependence(k=_u(rng, 0.3, 1.0), rate_ref_v_per_s=_u(rng, 500, 3000))
        laws = [n for n, c in LAWS.items() if getattr(c, "rate_capable", False)]
    if "delay" in designs:
        eff["delay"] = int(round(_u(rng, 0.2e-3, 2e-3) * FS_HZ))
    if "amplifier_slew_limit" in designs:
        eff["slew"] = _u(rng, 1500, 6000)
    if "amplifier_bandwidth" in designs:
        eff["fc"] = _u(rng, 100, 400)
    if "unmodeled_resonance" in designs:
        eff["res"] = Mode(_u(rng, 800, 3500), _u(rng, 0.01, 0.05), _u(rng, 0.02, 0.10) * rng.choice([-1, 1]))
    if "saturation" in designs:
        side = int(rng.choice([-1, 1]))
        margin = _u(rng, 5, 15)
        if side > 0:
            rail = _u(rng, 115, 140)
            hi = rail - margin
        else:
            rail = _u(rng, 10, 35)
            lo = rail + margin
        eff["sat"] = (side, rail)
    if "asymmetric_hysteresis" in designs:
        side = int(rng.choice([-1, 1]))
        if side > 0:
            knee = _u(rng, 115, 135)
            hi = knee - _u(rng, 0, 5)
        else:
            knee = _u(rng, 15, 35)
            lo = knee + _u(rng, 0, 5)
        eff["asym"] = (side, knee)

    slow = [d for d in designs if d in SLOW_CAL]
    if slow:
        # slow calibration, fast reveal; modes kept >= 4x above the reveal band
        tops = []
        for d in slow:
            if d == "rate_dependent_hysteresis":
                tops.append((0.1 * eff["rate"].rate_ref_v_per_s / (2 * np.pi * 1.0), 40.0))
            elif d == "delay":
                tops.append((_u(rng, 10, 30), _u(rng, 100, 300)))
            elif d == "amplifier_slew_limit":
                tops.append((0.4 * eff["slew"] / (2 * np.pi * 1.0), 250.0))
            else:
                tops.append((eff["fc"] / 8, 1.5 * eff["fc"]))
        cal_top = min(t[0] for t in tops)
        rev_top = max(t[1] for t in tops)
        f1_min = max(f1_min, 4 * rev_top)
    stage = _draw_stage(rng, laws, f1_min)
    if "unmodeled_resonance" in designs:
        # the stage's own modes sit well below the unmodeled one
        r = eff["res"]
        for m in stage.modes:
            m.f_hz = min(m.f_hz, r.f_hz / _u(rng, 2.5, 4))
        if f1_min > min(m.f_hz for m in stage.modes):      # keep slow-design constraints
            r.f_hz = max(r.f_hz, 3 * f1_min)
        cal_top_res = r.f_hz / 2.5
        cal_top = cal_top_res if cal_top is None else min(cal_top, cal_top_res)
        info["resonance"] = {"f_hz": r.f_hz, "zeta": r.zeta, "residue": r.r}
    if cal_top is None:
        cal_top = min(1.3 * max(m.f_hz for m in stage.modes), 4500.0)

    # ---- effects on the stage (sizes drawn from the stated ranges)
    stroke = stage.stroke_um
    if "creep" in truth:
        stage.creep = Creep(g=_u(rng, 0.005, 0.02), t0_s=_u(rng, 0.01, 0.1), t1_s=_u(rng, 5, 30))
        info["creep"] = dataclasses.asdict(stage.creep)
    if "rate_dependent_hysteresis" in truth:
        stage.rate = eff["rate"]
        info["rate"] = dataclasses.asdict(stage.rate)
    if "delay" in truth:
        stage.delay_samples = 1 + eff["delay"]
        info["delay_ms"] = eff["delay"] / FS_HZ * 1e3
    if "amplifier_slew_limit" in truth:
        stage.slew_v_per_s = eff["slew"]
        info["slew_v_per_ms"] = eff["slew"] / 1e3
    if "amplifier_bandwidth" in truth:
        stage.amp_fc_hz = eff["fc"]
        info["amp_fc_hz"] = eff["fc"]
    if "unmodeled_resonance" in truth:
        r = eff["res"]
        stage.modes[0].r -= r.r
        stage.modes.append(r)
    if "saturation" in truth:
        side, rail = eff["sat"]
        stage.rails_v = (AMP_RAILS_V[0], rail) if side > 0 else (rail, AMP_RAILS_V[1])
        info["rail_v"] = rail
    if "asymmetric_hysteresis" in truth:
        side, knee = eff["asym"]
        # extra displacement at 30 V beyond the knee: 2..8 % of the stroke
        a = _u(rng, 0.02, 0.08) * stroke
        stage.asym = Asymmetry(a_um=a, p=_u(rng, 1.5, 2.5), r_v=_u(rng, 2, 6), knee_v=knee, side=side)
        info["asym"] = dataclasses.asdict(stage.asym)
    if "cross_coupling" in truth:
        stage.coupling = Coupling(c=_u(rng, 0.01, 0.10) * rng.choice([-1, 1]), k2_um_per_v=_u(rng, 15, 100) / 150,
                                  f2_hz=_u(rng, 200, 1500), zeta2=_u(rng, 0.02, 0.1))
        info["coupling"] = dataclasses.asdict(stage.coupling)
    if "sensor_offset" in truth:
        d = _u(rng, 0.1, 1.0) * rng.choice([-1, 1])
        stage.sensor.offset_by_session[1] = stage.sensor.offset_by_session[0] + d
        info["offset_change_um"] = d
    if "sensor_nonlinearity" in truth:
        dev = _u(rng, 0.003, 0.015)          # largest deviation, fraction of the stroke
        stage.sensor.nl_by_session[1] = stage.sensor.nl_by_session[0] + 2 * dev * rng.choice([-1, 1])
        info["sensor_nl_of_stroke"] = dev

    # ---- calibration recordings
    c = (lo + hi) / 2
    cal: list[Rec] = []
    creep_design = "creep" in designs
    drift_design = "thermal_drift" in designs
    short = drift_design
    dur = (lambda a, b: S * _u(rng, a, b)) if not short else (lambda a, b: S * _u(rng, 4, 7))
    kinds = ["triangles", "small_triangles"] if creep_design else \
        list(rng.permutation(["decaying_sine", "forc", "random_walk", "triangles"]))[:int(rng.integers(3, 5))]
    rate_cap = None                            # largest calibration drive rate [V/s]
    if slow:
        rate_cap = 0.1 * eff["rate"].rate_ref_v_per_s if "rate_dependent_hysteresis" in designs else None
        if "amplifier_slew_limit" in designs:
            rate_cap = min(rate_cap or 1e9, 0.4 * eff["slew"])
    span = hi - lo

    def fcap(f, pp=span):                      # frequency that keeps a pp [V] signal below rate_cap
        return f if rate_cap is None else min(f, rate_cap / (np.pi * pp))

    for k in kinds:
        if k == "decaying_sine":
            f = _u(rng, 1.0, 5.0) if creep_design else _u(rng, 0.5, 5.0)
            u = sg.decaying_sine(dur(8, 15), fcap(f), lo, hi, _u(rng, 2, 6) * S)
        elif k == "forc":
            rate = min(_u(rng, 50, 300) / max(S, 0.25), rate_cap or 1e9)
            u = sg.forc(lo, hi, int(rng.integers(6, 13)), rate, start_v=c)
        elif k == "random_walk":
            u = sg.random_walk(dur(8, 15), lo, hi, fcap(_u(rng, 0.5, 3.0), span / 4), rng)
        elif k == "small_triangles":          # creep design: periodic, after a warm-up
            f, a = _u(rng, 2.0, 4.0), _u(rng, 0.15, 0.3) * span
            u = sg.triangle(round(dur(8, 15) * f) / f, f, c - a, c + a)
        else:
            f = fcap(_u(rng, 1.0, 2.0) if creep_design else _u(rng, 0.2, 2.0))
            d = dur(8, 15)
            u = sg.triangle(round(d * f) / f if creep_design else d, f, lo, hi)
        cal.append(Rec(f"cal_{k}", u, None, 0.0, 0, 0.0, 20.0 if creep_design else 0.0))
    amp = _u(rng, 1.0, 4.0)
    if rate_cap is not None:
        cal_top = min(cal_top, rate_cap / (2 * np.pi * amp))
    cal.append(Rec("cal_chirp", sg.chirp(S * _u(rng, 4, 6), min(2.0, cal_top / 4), cal_top, amp,
                                         _u(rng, lo + 0.3 * span, hi - 0.3 * span)), None, 0.0, 0, 0.0))
    info["calibration_top_hz"] = cal_top
    info["calibrated_range_v"] = (lo, hi)

    # ---- reveal recordings
    rev: list[Rec] = []
    r_lo, r_hi = lo, hi

    def inrange(a, b):
        return lo + a * span, lo + b * span

    for d in designs:
        if d == "creep":
            n = int(rng.integers(5, 9))
            levels = rng.uniform(lo + 0.05 * span, hi - 0.05 * span, n)
            levels[1::2] = hi - (levels[1::2] - lo)       # alternate low and high
            rev.append(Rec("rev_steps_dwell", sg.steps(levels, max(S * _u(rng, 3, 8), 2.0), _u(rng, 0.01, 0.03)), None, 0, 1, 0))
        elif d == "thermal_drift":
            rev.append(Rec("rev_long_triangle", sg.triangle(S * _u(rng, 30, 50), _u(rng, 0.2, 1.0), lo, hi), None, 0, 1, 0))
            rev.append(Rec("rev_long_walk", sg.random_walk(S * _u(rng, 20, 30), lo, hi, _u(rng, 0.3, 1.5), rng), None, 0, 1, 0))
        elif d == "sensor_offset":
            rev.append(Rec("rev_session2_triangle", sg.triangle(S * _u(rng, 10, 20), _u(rng, 0.3, 2), lo, hi), None, 0, 1, 0))
            rev.append(Rec("rev_session2_walk", sg.random_walk(S * _u(rng, 10, 20), lo, hi, _u(rng, 0.5, 2), rng), None, 0, 1, 0))
        elif d == "cross_coupling":
            T = S * _u(rng, 10, 20)
            u2 = sg.sines([_u(rng, 1, 5), _u(rng, 10, 50)], _u(rng, 30, 70), 75.0, T / 2)
            u = sg.triangle(u2.size / FS_HZ, _u(rng, 0.2, 1.0), *inrange(0.2, 0.8))
            rev.append(Rec("rev_other_axis_moving", u, u2, 0, 1, 0))
            u2b = sg.triangle(S * _u(rng, 8, 12), _u(rng, 0.5, 5), 0, 150)
            rev.append(Rec("rev_hold_other_axis_moving", sg.hold(u2b.size / FS_HZ, _u(rng, lo + 0.2 * span, hi - 0.2 * span)), u2b, 0, 1, 0))
        elif d == "rate_dependent_hysteresis":
            rr = eff["rate"].rate_ref_v_per_s
            a = 0.4 * span
            fs_ = [min(40.0, x * rr / (2 * np.pi * a)) for x in (0.5, 1.5, 4.0)]
            rev.append(Rec("rev_fast_sines", sg.sines(fs_, a, c, S * _u(rng, 4, 6)), None, 0, 1, 0))
            rev.append(Rec("rev_slow_triangle", sg.triangle(S * _u(rng, 6, 10), _u(rng, 0.2, 1), lo, hi), None, 0, 1, 0))
        elif d == "unmodeled_resonance":
            n = int(rng.integers(6, 12))
            rev.append(Rec("rev_steps", sg.steps(rng.uniform(lo + 0.1 * span, hi - 0.1 * span, 4 * n), S * _u(rng, 0.15, 0.4)), None, 0, 1, 0))
            fr = eff["res"].f_hz
            rev.append(Rec("rev_chirp_wide", sg.chirp(S * _u(rng, 4, 8), fr / 4, min(1.3 * fr, 4800.0), _u(rng, 2, 5), c), None, 0, 1, 0))
        elif d == "delay":
            f = np.geomspace(_u(rng, 20, 40), rev_top, 4)
            rev.append(Rec("rev_fast_sines", sg.sines(f, _u(rng, 5, 20), c, S * _u(rng, 2, 4)), None, 0, 1, 0))
            rev.append(Rec("rev_fast_triangle", sg.smooth(sg.triangle(S * _u(rng, 5, 8), _u(rng, 10, 30), *inrange(0.2, 0.8)), rev_top), None, 0, 1, 0))
        elif d == "amplifier_slew_limit":
            sr = eff["slew"]
            a = 0.4 * span
            f = [x * sr / (2 * np.pi * a) for x in (_u(rng, 1.5, 2.5), _u(rng, 2.5, 4))]
            rev.append(Rec("rev_fast_large_sines", sg.sines(f, a, c, S * _u(rng, 3, 5)), None, 0, 1, 0))
            n = int(rng.integers(5, 9))
            rev.append(Rec("rev_large_steps", sg.steps(np.resize([lo + 0.1 * span, hi - 0.1 * span], n), S * _u(rng, 0.5, 1.0), _u(rng, 0.003, 0.005)), None, 0, 1, 0))
        elif d == "amplifier_bandwidth":
            fc = eff["fc"]
            f = np.geomspace(fc / 4, 1.5 * fc, 4)
            rev.append(Rec("rev_sines", sg.sines(f, _u(rng, 3, 10), c, S * _u(rng, 2, 4)), None, 0, 1, 0))
            rev.append(Rec("rev_chirp", sg.chirp(S * _u(rng, 4, 6), fc / 10, 1.5 * fc, _u(rng, 2, 5), c), None, 0, 1, 0))
        elif d == "sensor_nonlinearity":
            rev.append(Rec("rev_session2_triangle", sg.triangle(S * _u(rng, 10, 20), _u(rng, 0.3, 2), lo, hi), None, 0, 1, 0))
            n = int(rng.integers(6, 10))
            rev.append(Rec("rev_session2_steps", sg.steps(rng.uniform(lo, hi, n), S * _u(rng, 1, 2), 0.01), None, 0, 1, 0))
        elif d == "saturation":
            side, rail = eff["sat"]
            r_lo, r_hi = (lo, min(150.0, rail + _u(rng, 10, 35))) if side > 0 else (max(-20.0, rail - _u(rng, 10, 35)), hi)
            rev.append(Rec("rev_beyond_range_triangle", sg.triangle(S * _u(rng, 8, 15), _u(rng, 0.3, 2), r_lo, r_hi), None, 0, 1, 0))
            rev.append(Rec("rev_beyond_range_sine", sg.decaying_sine(S * _u(rng, 8, 12), _u(rng, 0.5, 3), r_lo, r_hi, 1e9), None, 0, 1, 0))
        elif d == "asymmetric_hysteresis":
            side, knee = eff["asym"]
            r_lo, r_hi = (lo, min(knee + 30.0, AMP_RAILS_V[1])) if side > 0 else (knee - 30.0, hi)
            rev.append(Rec("rev_beyond_range_triangle", sg.triangle(S * _u(rng, 8, 15), _u(rng, 0.3, 2), r_lo, r_hi), None, 0, 1, 0))
            rev.append(Rec("rev_beyond_range_walk", sg.random_walk(S * _u(rng, 8, 12), r_lo, r_hi, _u(rng, 0.5, 2), rng), None, 0, 1, 0))
    # a slow in-range triangle in every reveal set (the effect must not be needed there)
    rev.append(Rec("rev_slow_triangle_in_range", sg.triangle(S * _u(rng, 5, 8), _u(rng, 0.3, 1.0), lo, hi), None, 0, 1, 0))
    info["reveal_range_v"] = (min(r_lo, lo), max(r_hi, hi))

    # ---- session clock, holds, other axis
    t = 0.0
    for r in cal:
        r.t_session, r.pre_s = t, (_u(rng, 120, 200) if creep_design else _u(rng, 5, 30))
        t += r.u.size / FS_HZ + _u(rng, 2, 10)
    if drift_design:
        t_on = t + _u(rng, 0, 20)
        tau = _u(rng, 20, 200)
        t += _u(rng, 20, 40)
    for r in rev:
        r.t_session, r.pre_s = t, (S * _u(rng, 1, 3) if creep_design else _u(rng, 5, 30))
        t += r.u.size / FS_HZ + _u(rng, 2, 10)
    if "thermal_drift" in truth:
        t_rev0, t_rev1 = rev[0].t_session, t
        target = _u(rng, 0.05, 0.5) * rng.choice([-1, 1])      # change over the reveal [um]
        a = target / max(1 - np.exp(-(t_rev1 - t_on) / tau) - (1 - np.exp(-max(t_rev0 - t_on, 0) / tau)), 1e-3)
        nb = int(rng.integers(1, 4))
        stage.drift = Drift(a_um=float(a), t_on_s=float(t_on), tau_s=float(tau),
                            b_um=tuple(abs(target) * rng.uniform(0.1, 0.3, nb)),
                            p_s=tuple(rng.uniform(30, 300, nb)), ph=tuple(rng.uniform(0, 2 * np.pi, nb)))
        info["drift_change_over_reveal_um"] = target
        info["drift"] = dataclasses.asdict(stage.drift)
    has_u2 = "cross_coupling" in designs or rng.random() < 0.3
    if has_u2:
        u2_hold = _u(rng, 0, 150)
        for r in cal:
            r.u2 = np.full(r.u.size, u2_hold)
        if "cross_coupling" not in designs:      # the other axis moves, but nothing couples
            T = rev[-1].u.size / FS_HZ
            rev[-1].u2 = sg.sines([_u(rng, 0.5, 3)], _u(rng, 20, 60), 75.0, T)[:rev[-1].u.size]
        for r in rev:
            if r.u2 is None:
                r.u2 = np.full(r.u.size, u2_hold)
    info["law"] = stage.law.describe()
    info["modes"] = [dataclasses.asdict(m) for m in stage.modes]
    info["stroke_um"] = stroke
    info["noise_um"] = stage.sensor.noise_um
    label = "+".join(truth) if truth else "none"
    return Case(f"s{seed}-{index:03d}-{label}", truth, design, stage, cal, rev, info)


def write_case(case: Case, directory: str, seed_noise: int = 0) -> dict:
    """Simulate a case and write its recordings as CSV files.

    Returns
    -------
    dict
        ``calibration`` and ``recordings`` (lists of paths), ``truth`` (list of effect
        names, empty for a null), ``law``, ``design``, ``info``.
    """
    os.makedirs(directory, exist_ok=True)
    out = {"calibration": [], "recordings": []}
    rng = np.random.default_rng([seed_noise, zlib.crc32(case.case_id.encode())])
    for group, recs in (("calibration", case.calibration), ("recordings", case.reveal)):
        for k, r in enumerate(recs):
            n = r.u.size
            u2 = r.u2
            if r.warmup_s > 0:                 # periodic drive: run it before, keep the end
                reps = int(np.ceil(r.warmup_s * FS_HZ / n)) + 1
                uu = np.tile(r.u, reps)
                u2u = None if u2 is None else np.tile(u2, reps)
                y = case.stage.run(uu, u2u, r.t_session - (reps - 1) * n / FS_HZ, r.session, r.pre_s, rng)[-n:]
            else:
                y = case.stage.run(r.u, u2, r.t_session, r.session, r.pre_s, rng)
            t = np.arange(n) / FS_HZ
            cols = {"t": t, "u": r.u, "y": y}
            if u2 is not None:
                cols["u2"] = u2
            path = os.path.join(directory, f"{'cal' if group == 'calibration' else 'rev'}{k}_{r.name}.csv")
            save_recording(path, cols, meta={"sample_rate_hz": int(FS_HZ), "source": "piezoctl.foreign",
                                             "case": case.case_id, "session": r.session,
                                             "session_time_s": f"{r.t_session:.3f}"}, precision=9)
            out[group].append(path)
    out.update(truth=list(case.truth), law=case.stage.law.name, design=case.design, info=case.info)
    return out
