"""What the true effect would reach on a kept creep, drift, coupling, concealed-mode, asymmetry, delay, bandwidth,
sensor offset, rate or sensor curve case (docs/diagnose-rounds/round-22.md, "Round 22: held-out ratios above 0.7"; every effect after
the first four since round 26; the drift begins after the calibration, so its base fitted without it is the kept one).

A kept case directory of ``tools/bench-diagnose --foreign --keep DIR`` (``sSSS-III-EFFECT`` with the recordings and
``out/``) is drawn again from its seed and index (scale 0.5, as the held-out runs; the kept recordings are
reproduced to the sensor's noise, which is checked), then written again with the effect switched off: the same
case id, so the same noise stream. The base is fitted on that calibration as ``diagnose`` fits it (``fit_base``,
settle 0.5 s). The refined model "base fitted without the effect + the true effect" errs on the real reveal
recordings exactly by ``y_off - base_off(u)``, so

- ``truth`` = RMS(y_off - base_off) / RMS(y - base): the ratio an exact term would reach (all data, settled
  samples, every reveal recording; not the two-fold held-out figure, which is printed beside it as ``heldout``);
- ``refined`` = RMS(y - refined) / RMS(y - base) of the kept refined model on the same samples;
- ``*_acting``: the same on the samples the effect changes (the noise-free reading with the effect minus without
  it, less its mean per recording, beyond 2 noise);
- ``*_beyond_level``: the same with each model's error less its mean per recording (the level a recording starts
  at: the hysteresis state the unknown history before it left);
- ``kept`` (round 25) = RMS(y - base - e) / RMS(y - base), ``e`` the effect on the stage (the noise-free reading
  with it minus without): the *kept* base (the one the diagnosis tested against) plus the exact effect. ``truth``
  refits the base without the effect, which for a mode changes the base too (s132-037's 1.14, round 24); ``kept``
  does not;
- for a mode (round 25), ``branch_fixed`` and ``branch_fit``: the kept base plus the term's own branch
  ``r (M(w) - w)`` (``UnmodeledResonance.basis`` at the true frequency and damping, on the kept base's ``w``), its
  gain the true residue times G's static gain, or its two gains least-squared on these samples (in-sample: a
  floor for what the term at the true setting can reach, not a held-out figure).

``truth`` near ``refined``: the term's model is not the limit; ``truth`` above 0.7: the base's misfit is.

    .venv/bin/python -m piezoctl.bench.effect_oracle /tmp/ho127/s127-019-cross_coupling ...
"""

from __future__ import annotations

import copy
import glob
import json
import os
import sys
import tempfile
import time

import numpy as np

SETTLE_S = 0.5
ACTING_NOISE = 2.0       # a sample is acted on where the effect changes it by more than this many noise RMS

ORACLE_EFFECTS = ("creep", "thermal_drift", "cross_coupling", "unmodeled_resonance", "asymmetric_hysteresis", "delay",
                  "amplifier_bandwidth", "sensor_offset", "rate_dependent_hysteresis", "sensor_nonlinearity")
# the case's ``info`` key that states each effect's size (printed with the figures)
_INFO_KEY = {"creep": "creep", "thermal_drift": "drift", "cross_coupling": "coupling", "unmodeled_resonance": "modes",
             "asymmetric_hysteresis": "asym", "delay": "delay_ms", "amplifier_bandwidth": "amp_fc_hz",
             "sensor_offset": "offset_change_um", "rate_dependent_hysteresis": "rate",
             "sensor_nonlinearity": "sensor_nl_of_stroke"}

__all__ = ["ORACLE_EFFECTS", "model_error", "switch_off", "branch_ratios", "oracle_case", "main"]


def model_error(params: dict, rec) -> np.ndarray:
    """The reading less a model's output on one recording [um], the model run on the recording's session clock
    (``io.recording.session_start``) as ``diagnose`` runs it: a drift on that clock (``ThermalDrift``) simulated on
    the recording's own clock restarts with each recording (round 28: s140-016's kept refined model read 1.57 so,
    against the tool's 0.73 on all data)."""
    from ..ident import refined
    from ..io.recording import session_start
    return rec.y - refined.simulate(params, rec.t, rec.u, rec.u2, session_start(rec))


def _noise_free(stage, rec) -> np.ndarray:
    """The stage's reading of one recording without noise and quantization [um]."""
    st = copy.deepcopy(stage)
    st.sensor.noise_um, st.sensor.lsb_um = 0.0, 1e-9
    x = st.displacement(rec.u, rec.u2, rec.t_session, rec.pre_s)
    return st.sensor.read(x, rec.session, 0.5 * st.stroke_um, 0.5 * st.stroke_um, np.random.default_rng(0))


def _ratio(after, before) -> float:
    b = float(np.sum(before ** 2))
    return float(np.sqrt(np.sum(after ** 2) / b)) if b > 0 else float("nan")


def _less_level(parts) -> np.ndarray:
    return np.concatenate([p - p.mean() for p in parts])


def switch_off(stage, effect: str) -> None:
    """Switch the concealed ``effect`` off in ``stage`` (in place) with ``foreign.cases.switch_off``, the switch
    ``Case.without_effects`` applies to every effect; effects outside :data:`ORACLE_EFFECTS` raise ``ValueError``."""
    from ..foreign.cases import switch_off as switch_one
    if effect not in ORACLE_EFFECTS:
        raise ValueError(f"no oracle for {effect}")
    switch_one(stage, effect)


def branch_ratios(resid, cols, true_gain: float) -> tuple[float, float]:
    """(fixed, fit): RMS of the kept base's error ``resid`` [um] after the mode branch ``cols`` (samples x 2, the
    term's two columns, :meth:`UnmodeledResonance.basis`) with the first column's gain ``true_gain`` [-], and after
    both columns with least-squares gains, each over RMS(resid). In-sample; ``nan`` for a zero error."""
    resid = np.asarray(resid, float)
    cols = np.asarray(cols, float)
    fit = resid - cols @ np.linalg.lstsq(cols, resid, rcond=None)[0]
    return _ratio(resid - true_gain * cols[:, 0], resid), _ratio(fit, resid)


def oracle_case(d: str) -> dict:
    """The oracle figures of one kept case directory ``d`` (module doc); errors in um."""
    from ..foreign.cases import draw_case, write_case
    from ..ident import refined
    from ..ident.base import fit_base
    from ..ident.terms import UnmodeledResonance
    from ..io.recording import load_recording
    name = os.path.basename(os.path.normpath(d))
    seed, index, effect = int(name[1:4]), int(name[5:8]), name[9:]
    if effect not in ORACLE_EFFECTS:
        raise ValueError(f"{name}: only {', '.join(ORACLE_EFFECTS)} cases")
    case = draw_case(seed, index, (effect,), scale=0.5)
    off = copy.deepcopy(case)
    switch_off(off.stage, effect)
    with tempfile.TemporaryDirectory(prefix="effect-oracle-") as tmp:
        files = write_case(off, tmp)
        cal_off = [load_recording(p) for p in files["calibration"]]
        rev_off = [load_recording(p) for p in files["recordings"]]
    base_off = fit_base(cal_off, settle_s=SETTLE_S, holdout=True)
    base_off.pop("base_info", None)
    base_off.pop("_holdout", None)
    base = json.load(open(os.path.join(d, "out", "base_model.json")))["params"]
    ref = json.load(open(os.path.join(d, "out", "refined_model.json")))["params"]
    diag = json.load(open(os.path.join(d, "out", "diagnosis.json")))
    hit = [e for e in diag["effects"] if e["name"] == effect and e.get("significant")]
    heldout = (hit[0]["improvement"]["nrmse_after"] / hit[0]["improvement"]["nrmse_before"]) if hit else None
    noise = case.stage.sensor.noise_um
    R, T, F, A, E, C, rows, check = [], [], [], [], [], [], [], []
    mode = case.info.get("resonance") if effect == "unmodeled_resonance" else None
    for spec, path, ro in zip(case.reveal, sorted(glob.glob(os.path.join(d, "rev*.csv"))), rev_off):
        rec = load_recording(path)
        m = rec.t >= SETTLE_S
        y_with = _noise_free(case.stage, spec)
        check.append(float(np.std(rec.y - y_with) / noise))
        r = model_error(base, rec)[m]
        t = model_error(base_off, ro)[m]
        f = model_error(ref, rec)[m]
        e = (y_with - _noise_free(off.stage, spec))[m]
        a = np.abs(e - e.mean()) > ACTING_NOISE * noise
        rows.append({"recording": os.path.basename(path), "base_um": float(np.sqrt(np.mean(r ** 2))),
                     "base_level_um": float(r.mean()), "truth_um": float(np.sqrt(np.mean(t ** 2))),
                     "refined_um": float(np.sqrt(np.mean(f ** 2))), "refined_level_um": float(f.mean()),
                     "effect_um": float(np.std(e)), "acting": float(a.mean())})
        R.append(r), T.append(t), F.append(f), A.append(a), E.append(e)
        if mode:
            w = refined.simulate_parts(base, rec.t, rec.u, rec.u2)["w"]
            C.append(UnmodeledResonance.basis(w, mode["f_hz"], mode["zeta"], rec.dt)[m])
    if max(check) > 1.2:
        raise ValueError(f"{name}: the drawn case does not reproduce the kept recordings (noise x{max(check):.2f})")
    act = np.concatenate(A)
    Rc, Tc, Fc, Ec = (np.concatenate(x) for x in (R, T, F, E))
    out = {"case": name, "law": case.stage.law.name, "heldout": heldout, "truth": _ratio(Tc, Rc),
           "refined": _ratio(Fc, Rc), "acting": float(act.mean()),
           "truth_acting": _ratio(Tc[act], Rc[act]) if act.any() else None,
           "refined_acting": _ratio(Fc[act], Rc[act]) if act.any() else None,
           "truth_beyond_level": _ratio(_less_level(T), _less_level(R)),
           "refined_beyond_level": _ratio(_less_level(F), _less_level(R)),
           "kept": _ratio(Rc - Ec, Rc), "kept_acting": _ratio((Rc - Ec)[act], Rc[act]) if act.any() else None,
           "noise_um": noise, "effect": case.info.get(_INFO_KEY[effect]), "rows": rows}
    if mode:
        b, a = (np.asarray(base["dynamics"][k], float) for k in ("b", "a"))
        gain = mode["residue"] * b.sum() / a.sum()   # the residue of the static gain, in G's units
        out["branch_fixed"], out["branch_fit"] = branch_ratios(Rc, np.concatenate(C), gain)
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    for d in argv:
        t0 = time.time()
        c = oracle_case(d)
        f = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
        print(f"{c['case']} {c['law']}: held-out {f(c['heldout'])}; all data: truth {f(c['truth'])}, refined "
              f"{f(c['refined'])}; acting ({c['acting']:.2f}) {f(c['truth_acting'])}/{f(c['refined_acting'])}; "
              f"beyond a level per recording {f(c['truth_beyond_level'])}/{f(c['refined_beyond_level'])} "
              f"({time.time() - t0:.0f} s)", flush=True)
        print(f"    kept base + exact effect {f(c['kept'])} (acting {f(c['kept_acting'])})"
              + (f"; kept base + the true branch r (M(w) - w): {f(c['branch_fixed'])}, "
                 f"its gains fitted {f(c['branch_fit'])}"
                 if "branch_fit" in c else ""), flush=True)
        for r in c["rows"]:
            print(f"    {r['recording']:40s} base {1000 * r['base_um']:5.0f} nm (level {1000 * r['base_level_um']:+5.0f}), "
                  f"truth {1000 * r['truth_um']:5.0f}, refined {1000 * r['refined_um']:5.0f} (level "
                  f"{1000 * r['refined_level_um']:+5.0f}), effect {1000 * r['effect_um']:4.0f} (acting {r['acting']:.2f})",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
