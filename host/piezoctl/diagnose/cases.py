"""Concealed-effect cases built with the C stage model (docs/diagnose.md).

Each case is a stage where one vocabulary effect is present but the calibration
recordings do not show it (the drive stays where the effect is invisible, or the
calibration session did not have it), and "reveal" recordings that show it.
Null cases have nothing the base model lacks. Stage parameter files are written
as small JSON files next to the recordings; the recordings are generated at run
time (nothing large is stored).

Signals (10 kHz, drive in 0..150 V, the DAC's range):

- ``static``: a sine of ``f`` Hz whose amplitude shrinks linearly to 20 % (nested loops);
- ``chirp``: logarithmic sweep ``f0 -> f1`` with amplitude ``min(amp, rate / (2 pi f))``
  (the drive rate stays below ``rate`` V/s);
- ``steps``: random levels held 0.6-1.8 s, edges one sample long;
- ``triangle``: a symmetric triangle of ``f`` Hz;
- ``sine``: a sine of ``f`` Hz.
"""

from __future__ import annotations

import copy
import json
import os
from pathlib import Path

import numpy as np

__all__ = ["CASES", "MULTI_CASES", "FAST_CASES", "make_case", "signal", "stage_dict"]

FS = 10_000.0


def _hyst(kind="std", a2=0.0, rate=None):
    h = {"enabled": True, "v_ref": 150.0, "alpha": 0.32, "beta": 2.2, "gamma": 0.6, "a2": a2, "a3": 0.0,
         "rate": {"enabled": False, "gain": 0.3, "ref_v_per_s": 10000.0}}
    if kind == "sharp":  # saturates within ~15 V: small calibration loops already show its full shape
        h.update(alpha=1.2, beta=8.0, gamma=2.0)
    if rate is not None:
        h["rate"] = {"enabled": True, "gain": rate[0], "ref_v_per_s": rate[1]}
    return h


def _axis(**kw):
    ax = {
        "dac": {"enabled": True, "bits": 16, "range_v": [0.0, 10.0]},
        "delay": {"enabled": False, "samples": 1},
        "amplifier": {"gain": 15.0, "offset_v": 0.0,
                      "bandwidth": {"enabled": False, "hz": 2000.0},
                      "slew_rate": {"enabled": False, "current_limit_a": 0.1, "load_capacitance_f": 1.5e-6},
                      "saturation": {"enabled": False, "range_v": [-20.0, 150.0]}},
        "hysteresis": _hyst(),
        "creep": {"enabled": False, "terms": [{"tau_s": 1.0, "gain": 0.0}]},
        "actuator": {"gain_um_per_v": 0.11},
        "mechanics": {"enabled": True, "modes": [{"freq_hz": 600.0, "damping": 0.03, "gain": 1.0}]},
        "thermal": {"enabled": False, "drift_um_per_k": 0.05, "delta_k": 0.5, "time_constant_s": 600.0},
        "sensor": {"enabled": False, "offset_um": 0.0, "gain_error": 0.0, "nonlinearity": 0.0,
                   "range_um": [0.0, 20.0]},
        "noise": {"enabled": True, "rms_um": 0.002},
        "adc": {"enabled": True, "bits": 16, "range_um": [-2.0, 22.0]},
    }
    for path, value in kw.items():
        node = ax
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
    return ax


def stage_dict(name: str, axes: int = 1, coupling=None, **axis_kw) -> dict:
    """Stage parameter document (docs/stage-model.md) on the ``ideal`` base.

    ``axis_kw``: keys ``block__field`` (double underscore) replaced in every axis.
    """
    doc = {"name": name, "base": "ideal", "sample_rate_hz": FS, "axes": [_axis(**axis_kw) for _ in range(axes)],
           "coupling": {"enabled": False}}
    if coupling is not None:
        doc["coupling"] = {"enabled": True, "into": [dict(coupling) for _ in range(axes)]}
    return doc


def signal(spec: dict, seed: int = 0) -> np.ndarray:
    """Drive samples [V] at 10 kHz for a signal spec (see the module notes).

    The first 0.4 s are a conditioning sweep (rest -> top -> bottom of the range -> the
    signal), as done before a measurement: it puts the hysteresis on a known branch.
    """
    u = _raw_signal(spec, seed)
    lo, hi = spec.get("range", (10.0, 140.0))
    n1, n2, n3 = int(0.15 * FS), int(0.15 * FS), int(0.1 * FS)
    if u.size > n1 + n2 + n3:
        u[:n1] = np.linspace(0.0, hi, n1)
        u[n1:n1 + n2] = np.linspace(hi, lo, n2)
        u[n1 + n2:n1 + n2 + n3] = np.linspace(lo, u[n1 + n2 + n3], n3)
    return u


def _raw_signal(spec: dict, seed: int = 0) -> np.ndarray:
    kind = spec["kind"]
    T = float(spec.get("T", 10.0))
    t = np.arange(int(round(T * FS))) / FS
    lo, hi = spec.get("range", (10.0, 140.0))
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    rng = np.random.default_rng(seed)
    if kind == "static":
        a = half * (1.0 - 0.8 * t / T)
        return mid + a * np.sin(2 * np.pi * spec.get("f", 1.0) * t)
    if kind == "chirp":
        f0, f1 = spec.get("f0", 5.0), spec.get("f1", 1000.0)
        k = np.log(f1 / f0) / T
        f = f0 * np.exp(k * t)
        ph = 2 * np.pi * f0 * (np.exp(k * t) - 1) / k
        amp = np.minimum(spec.get("amp", 20.0), spec.get("rate", 4000.0) / (2 * np.pi * f))
        return mid + amp * np.sin(ph)
    if kind == "steps":
        u = np.empty(t.size)
        i = 0
        level = mid
        while i < t.size:
            n = int(rng.uniform(0.6, 1.8) * FS)
            u[i:i + n] = level
            i += n
            level = rng.uniform(lo, hi)
        return u
    if kind == "triangle":
        f = spec.get("f", 20.0)
        ph = (t * f) % 1.0
        tri = np.where(ph < 0.5, 4 * ph - 1, 3 - 4 * ph)
        return mid + half * tri
    if kind == "sine":
        return mid + half * np.sin(2 * np.pi * spec.get("f", 2.0) * t)
    raise ValueError(f"unknown signal kind {kind!r}")


CAL_STD = [{"kind": "static", "f": 1.0, "T": 10.0}, {"kind": "chirp", "f0": 5.0, "f1": 1000.0, "T": 8.0}]
CAL_SLOW = [{"kind": "static", "f": 1.0, "T": 10.0}, {"kind": "chirp", "f0": 2.0, "f1": 20.0, "T": 8.0}]
CAL_NARROW = [{"kind": "static", "f": 1.0, "T": 10.0, "range": (55.0, 95.0)},
              {"kind": "chirp", "f0": 5.0, "f1": 1000.0, "T": 8.0, "amp": 10.0, "range": (55.0, 95.0)}]
REC_STD = [{"kind": "steps", "T": 15.0}, {"kind": "triangle", "f": 20.0, "T": 5.0},
           {"kind": "sine", "f": 2.0, "T": 8.0, "range": (8.0, 142.0)}]
U2_MOVING = [{"kind": "sine", "f": 25.0, "T": 15.0, "range": (30.0, 120.0)},
             {"kind": "triangle", "f": 7.0, "T": 5.0, "range": (20.0, 130.0)},
             {"kind": "steps", "T": 8.0, "range": (20.0, 130.0)}]

# name -> case. truth: effects present and concealed; stage: axis overrides; cal_stage / rec_stages:
# overrides for the calibration session / per reveal recording (the session differs).
CASES: dict[str, dict] = {
    "creep": {"truth": ["creep"],
              "stage": {"creep": {"enabled": True, "terms": [{"tau_s": 0.5, "gain": 0.02}, {"tau_s": 2.0, "gain": 0.02},
                                                            {"tau_s": 10.0, "gain": 0.03}]}},
              "cal": [{"kind": "static", "f": 5.0, "T": 10.0}, CAL_STD[1]]},
    "thermal_drift": {"truth": ["thermal_drift"],
                      "stage": {"thermal": {"enabled": True, "drift_um_per_k": 0.5, "delta_k": 2.0,
                                            "time_constant_s": 20.0}},
                      "cal_stage": {"thermal__enabled": False}, "cal": CAL_STD, "temp": True},
    "sensor_offset": {"truth": ["sensor_offset"], "stage": {}, "cal": CAL_STD,
                      "rec_stages": [{"sensor": {"enabled": True, "offset_um": v, "gain_error": 0.0,
                                                 "nonlinearity": 0.0, "range_um": [0.0, 20.0]}}
                                     for v in (0.3, -0.2, 0.15)]},
    "cross_coupling": {"truth": ["cross_coupling"], "axes": 2,
                       "coupling": {"static_percent": 1.0, "dynamic_percent": 5.0, "ref_freq_hz": 100.0,
                                    "position_slope_per_um": 0.02, "position_center_um": 9.0},
                       "stage": {}, "cal": CAL_STD, "u2_cal": 75.0, "u2_rec": U2_MOVING},
    "rate_dependent_hysteresis": {"truth": ["rate_dependent_hysteresis"],
                                  "stage": {"hysteresis": _hyst(rate=(1.0, 3000.0))},
                                  "cal": [{"kind": "static", "f": 0.5, "T": 10.0},
                                          {"kind": "chirp", "f0": 5.0, "f1": 1000.0, "T": 8.0, "amp": 3.0}],
                                  # inside the calibrated drive range (the 0.5 Hz calibration loop shrinks)
                                  "rec": [{"kind": "triangle", "f": 20.0, "T": 5.0, "range": (25.0, 125.0)},
                                          {"kind": "triangle", "f": 40.0, "T": 5.0, "range": (25.0, 125.0)},
                                          {"kind": "sine", "f": 2.0, "T": 8.0, "range": (25.0, 125.0)}]},
    # the stage's mode (1.5 kHz) lies far above the slow calibration's band (below 20 Hz), which sees a static
    # stage; the reveal steps and triangle corners ring at 1.5 kHz well above the noise
    "unmodeled_resonance": {"truth": ["unmodeled_resonance"],
                            "stage": {"mechanics": {"enabled": True, "modes": [
                                {"freq_hz": 1500.0, "damping": 0.02, "gain": 1.0}]}},
                            "cal": CAL_SLOW,
                            "rec": [{"kind": "steps", "T": 15.0, "range": (25.0, 125.0)},
                                    {"kind": "triangle", "f": 20.0, "T": 5.0, "range": (25.0, 125.0)},
                                    {"kind": "triangle", "f": 40.0, "T": 8.0, "range": (25.0, 125.0)}]},
    "delay": {"truth": ["delay"], "stage": {"delay": {"enabled": True, "samples": 10},
                                            "mechanics__enabled": False}, "cal": CAL_SLOW},
    "amplifier_slew_limit": {"truth": ["amplifier_slew_limit"],
                             "stage": {"amplifier__slew_rate": {"enabled": True, "current_limit_a": 0.015,
                                                                "load_capacitance_f": 1.5e-6}},
                             "cal": CAL_STD},
    "amplifier_bandwidth": {"truth": ["amplifier_bandwidth"],
                            "stage": {"amplifier__bandwidth": {"enabled": True, "hz": 300.0},
                                      "mechanics__enabled": False}, "cal": CAL_SLOW},
    "sensor_nonlinearity": {"truth": ["sensor_nonlinearity"],
                            "stage": {"hysteresis": _hyst("sharp"),
                                      "sensor": {"enabled": True, "offset_um": 0.0, "gain_error": 0.0,
                                                 "nonlinearity": 0.01, "range_um": [0.0, 20.0]}},
                            "cal": CAL_NARROW},
    "saturation": {"truth": ["saturation"],
                   "stage": {"hysteresis": _hyst("sharp"),
                             "amplifier__saturation": {"enabled": True, "range_v": [-20.0, 118.0]}},
                   "cal": [{"kind": "static", "f": 1.0, "T": 10.0, "range": (15.0, 110.0)},
                           {"kind": "chirp", "f0": 5.0, "f1": 1000.0, "T": 8.0, "range": (15.0, 110.0)}]},
    "asymmetric_hysteresis": {"truth": ["asymmetric_hysteresis"],
                              "stage": {"hysteresis": _hyst("sharp", a2=0.4)}, "cal": CAL_NARROW},
    # the stage's even term (a2) is in the base's cubic only over the calibrated range; beyond it the base goes on
    # as a line, and the tool names the missing bend asymmetric_hysteresis (as in that case). A null must therefore
    # calibrate over the whole reveal range, at every --scale (the shrinking sine's settled peaks included)
    "null_default": {"truth": [], "stage": {"hysteresis": _hyst(a2=0.15)},
                     "cal": [dict(CAL_STD[0], range=(0.0, 150.0)), CAL_STD[1]]},
    "null_slow": {"truth": [], "stage": {"mechanics__enabled": False}, "cal": CAL_SLOW},
    "null_narrow": {"truth": [], "stage": {"hysteresis": _hyst("sharp")}, "cal": CAL_NARROW},
    "null_two_axis": {"truth": [], "axes": 2, "stage": {}, "cal": CAL_STD, "u2_cal": 75.0, "u2_rec": U2_MOVING},
}

# two effects at once ("several effects may be present; list them all"): run with
# tools/bench-diagnose --cases multi (not in the default run, which is one effect per case)
MULTI_CASES: dict[str, dict] = {
    "delay+sensor_offset": {"truth": ["delay", "sensor_offset"],
                            "stage": {"delay": {"enabled": True, "samples": 10}, "mechanics__enabled": False},
                            "cal": CAL_SLOW, "rec_stages": CASES["sensor_offset"]["rec_stages"]},
    "creep+thermal_drift": {"truth": ["creep", "thermal_drift"],
                            "stage": {"creep": CASES["creep"]["stage"]["creep"],
                                      "thermal": CASES["thermal_drift"]["stage"]["thermal"]},
                            "cal_stage": {"thermal__enabled": False}, "cal": CASES["creep"]["cal"], "temp": True},
    "unmodeled_resonance+cross_coupling": {"truth": ["unmodeled_resonance", "cross_coupling"], "axes": 2,
                                           "coupling": CASES["cross_coupling"]["coupling"],
                                           "stage": CASES["unmodeled_resonance"]["stage"], "cal": CAL_SLOW,
                                           "u2_cal": 75.0, "u2_rec": U2_MOVING, "rec": CASES["unmodeled_resonance"]["rec"]},
}

# the subset tools/test runs (tests/host/test_diagnose.py, shorter signals and another seed than the benchmark):
# a null, a drift, a drive-side dynamics term, creep (nested test) and saturation (beyond the calibrated range)
FAST_CASES = ("null_default", "thermal_drift", "delay", "creep", "saturation")


def _scaled(specs, scale):
    out = []
    for s in specs:
        s = dict(s)
        s["T"] = float(s.get("T", 10.0)) * scale
        out.append(s)
    return out


def make_case(name: str, out_dir, scale: float = 1.0, seed: int = 0) -> dict:
    """Generate a case's stage files and recordings under ``out_dir``.

    Parameters
    ----------
    name : str
        A key of :data:`CASES` or :data:`MULTI_CASES`.
    out_dir : path-like
        Directory (created); receives ``stage*.json``, ``cal*.csv``, ``rec*.csv``.
    scale : float
        Multiplies every signal duration (1.0: 18 s of calibration, 28 s of reveal data).
    seed : int
        Seed of the step levels and the sensor noise.

    Returns
    -------
    dict
        ``calibration`` and ``recordings`` (paths), ``truth`` (list of effect names).
    """
    from ..io.recording import save_recording
    from ..sil.stage import simulate_stage
    case = CASES[name] if name in CASES else MULTI_CASES[name]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    axes = case.get("axes", 1)

    def write_stage(fname, overrides):
        kw = dict(case["stage"])
        kw.update(overrides or {})
        doc = stage_dict(f"{name}", axes, case.get("coupling"), **copy.deepcopy(kw))
        p = out / fname
        p.write_text(json.dumps(doc, indent=1))
        return p

    cal_stage = write_stage("stage_cal.json", case.get("cal_stage"))
    rec_stages = case.get("rec_stages")
    rec_specs = _scaled(case.get("rec", REC_STD), scale)
    cal_specs = _scaled(case["cal"], scale)
    u2_rec = _scaled(case.get("u2_rec", []), scale) if case.get("u2_rec") else None
    paths = {"calibration": [], "recordings": [], "truth": list(case["truth"]), "dir": str(out)}

    def run(stage_path, spec, i, fname, u2spec=None, u2const=None, temp=False):
        u = signal(spec, seed=seed * 100 + i)
        t = np.arange(u.size) / FS
        cols = {"t": t, "u": u}
        if axes == 2:
            if u2spec is not None:
                u2 = signal(dict(u2spec, T=spec["T"]), seed=seed * 100 + 50 + i)
            else:
                u2 = np.full(u.size, u2const if u2const is not None else 75.0)
            y, y2 = simulate_stage(stage_path, t, u, u2, seed=seed * 1000 + i + 1)
            cols.update(y=y, u2=u2, x2=y2)
        else:
            cols["y"] = simulate_stage(stage_path, t, u, seed=seed * 1000 + i + 1)
        if temp:
            th = json.loads(Path(stage_path).read_text())["axes"][0]["thermal"]
            cols["temp"] = 25.0 + (th["delta_k"] * (1 - np.exp(-t / th["time_constant_s"]))
                                   if th["enabled"] else 0.0 * t)
        p = out / fname
        save_recording(p, cols, meta={"sample_rate_hz": FS, "case": name, "signal": spec["kind"]})
        return str(p)

    for i, spec in enumerate(cal_specs):
        paths["calibration"].append(run(cal_stage, spec, i, f"cal{i + 1}.csv", u2const=case.get("u2_cal"),
                                        temp=case.get("temp", False)))
    for i, spec in enumerate(rec_specs):
        st = write_stage(f"stage_rec{i + 1}.json", rec_stages[i]) if rec_stages else write_stage("stage_rec.json", None)
        u2s = u2_rec[i % len(u2_rec)] if u2_rec else None
        paths["recordings"].append(run(st, spec, 10 + i, f"rec{i + 1}.csv", u2spec=u2s,
                                       u2const=case.get("u2_cal"), temp=case.get("temp", False)))
    with open(out / "case.json", "w") as fh:
        json.dump({k: v for k, v in paths.items()}, fh, indent=1)
    return paths


if __name__ == "__main__":  # pragma: no cover - manual use
    import sys
    print(make_case(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else os.getcwd()))
