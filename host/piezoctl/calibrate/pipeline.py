"""The seven steps of ``piezoctl calibrate`` (see ``docs/calibrate.md``).

Every step prints on stderr when it starts and when it ends (``Progress`` of
``commands/_options.py``), plus its result line and, in the longer steps, a
line per sub-step, so no step runs silently; ``--quiet`` and ``--json`` silence
them. The same lines (step, name, seconds, result) go to ``summary.json``'s
``steps`` and to the report's step table.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import pathlib
import time
import types

import numpy as np

from .. import __version__
from ..commands._options import Progress, progress
from ..commands.flash import flash_image
from ..errors import CliError
from ..ident import get_kind
from ..ident import tf as tfid
from ..ident.common import IdentError, Options, add_common_options, nrmse
from ..io.modelfile import load_model, make_provenance, save_model
from ..io.recording import load_recording, save_recording
from ..tables.from_model import compile_model
from ..tables.image import TableImageError, build_image
from . import excitation, ilc
from .dyninv import design_dyninv
from .feedback import design_feedback

__all__ = ["calibrate", "fit_model", "Steps"]

STEPS = 7
FREQS = (1.0, 10.0, 50.0, 100.0)
LEARNED = "learned"   # runs key: compensated plus the learned feedforward (ilc.py)
DYNINV = "dynamics_inverse"   # runs key: the hysteresis inverse and feedback with the dynamics inverse (dyninv.py)
RANDOM = "random"     # runs key of the random scan: a reference not known in advance
RANDOM_F_OF_RESONANCE = 0.4   # the random scan's band: up to this fraction of the resonance (and 300 Hz)
MAX_F_OF_RESONANCE = 0.4   # triangles up to this fraction of the resonance
ILC_TRIALS = {"slow": 4, "fast": 10}   # trials of a 1 s period (1 Hz, the multitone) and of a faster one
ILC_F_CUT = 2.0   # the learning's band edge, a multiple of the resonance


def _periods(f_hz: float) -> int:
    """Periods measured after settling: about 0.1 s of a fast triangle, one of a slow one
    (a 1 Hz period holds 10000 samples already; two cost a second in each of five configurations)."""
    return 1 if f_hz < 10 else max(5, int(round(0.1 * f_hz)))


class Steps:
    """Progress of the seven steps on stderr, and their record for the summary and the report.

    ``args`` is the command's namespace (``quiet``, ``json``, ``command``);
    ``None`` prints everything (a library caller, e.g. axis 2 of a two-axis
    calibration).
    """

    def __init__(self, args=None):
        self.args = args if args is not None else types.SimpleNamespace(quiet=False, json=False,
                                                                         command="calibrate")
        self.rows: list[dict] = []
        self._n = 0

    @contextlib.contextmanager
    def step(self, n: int, name: str):
        """``with steps.step(2, "excitation"):`` prints its start and end; records its duration [s]."""
        self._n = n
        row = {"step": n, "name": name, "result": "", "seconds": None}
        t0 = time.monotonic()
        with Progress(self.args, f"[{n}/{STEPS}] {name}"):
            yield row
            row["seconds"] = round(time.monotonic() - t0, 2)
        self.rows.append(row)

    def say(self, text: str) -> None:
        """A line of the current step (a sub-step starting, or a finding) on stderr."""
        progress(self.args, f"[{self._n}/{STEPS}] {text}")

    def result(self, row: dict, text: str) -> None:
        """The step's result: printed, and kept for the summary's ``steps``."""
        row["result"] = text
        self.say(text)


def _kind_options(kind: str, scale) -> Options:
    """Every option of ``kind``'s fit at its default (as ``identify`` would pass them), with the
    drive normalized to the controller's range."""
    mod = get_kind(kind)
    p = argparse.ArgumentParser(add_help=False)
    add_common_options(p)
    mod.add_options(p)
    opts = Options(vars(p.parse_args([])))
    opts["u_range"] = [float(scale.drive_min_v), float(scale.drive_max_v)]
    # what identify applies to the data itself, here nothing (kept for the same provenance)
    opts.update(delay_s=0.0, skip_s=0.0, drop_outliers=False)
    return opts


def fit_model(kind: str, recs: list, paths: list[str], out: pathlib.Path, scale) -> None:
    """Fit ``kind`` to the loaded recordings ``recs`` (read from ``paths``) and write the model file ``out``.

    The identification library directly (``piezoctl.ident``): the kind's ``fit`` with its default options
    and the drive range of the controller, provenance with the files' digests and the fit NRMSE per file.

    Raises
    ------
    CliError
        The fit failed (its reason).
    """
    mod = get_kind(kind)
    opts = _kind_options(kind, scale)
    t0 = time.perf_counter()
    try:
        params = dict(mod.fit(recs, opts))
    except (ValueError, np.linalg.LinAlgError) as exc:
        if isinstance(exc, CliError):
            raise
        raise IdentError(f"fitting {kind} failed: {exc}") from None
    params["input_delay_s"] = 0.0
    scores = [nrmse(r.y, mod.simulate(params, r.t, r.u)) for r in recs]
    prov = make_provenance(paths, dict(opts), nrmse=scores, rows=[len(r) for r in recs],
                           metrics={"fit_time_s": round(time.perf_counter() - t0, 3),
                                    "nrmse_definition": "RMS(yhat - y) / (max(y) - min(y)) over each fitted file"})
    save_model(out, kind, params, prov)


def _nrmse(y, yhat) -> float:
    return float(np.sqrt(np.mean((np.asarray(y) - np.asarray(yhat)) ** 2)) / np.ptp(y))


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _park(ctl, bottom_q15: int, seconds: float = 0.2, steps: int = 40) -> None:
    """Disarm after ramping the reference to ``bottom_q15`` (a drive in DIRECT
    mode, a position otherwise): dropping a raised drive to u_safe at once
    rings a low first mode (140 Hz on the two-axis stage) past the sensor's
    range, which latches the sensor fault."""
    st = ctl.status()
    if st["armed"]:
        q0 = st["reference_q15"]
        ctl.write("setpoint_q15", q0)
        ctl.write("ref_source", 0)
        for k in range(1, steps + 1):
            ctl.write("setpoint_q15", int(round(q0 + (bottom_q15 - q0) * k / steps)))
            time.sleep(seconds / steps)
    ctl.arm(False)


def drive_path_raw(ctl) -> None:
    """No input shaper, preview, dynamics inverse or learned feedforward (unit disarmed): they act on
    the reference in DIRECT mode too, so an excitation read as the drive needs them off, and a
    controller calibrated before keeps them (in its flash, or from an earlier session)."""
    ctl.configure_shaper()
    ctl.configure_dyninv()
    ilc.switch_off(ctl)


def _recover(ctl, faulted: list, label: str, say, run: dict | None = None, stop_faults: list | None = None) -> None:
    """After a configuration's runs: a fault (a reference that rang the stage past
    its sensor's range) is recorded in ``faulted`` and said, cleared, and the
    controller parked and armed again, so the next configuration starts clean.

    ``run`` (:func:`excitation.triangle_run` and friends): a fault that was not
    there when the run's record ended (``faults_in_record`` 0) latched when the
    host stopped a multisine, at a phase the host's speed set: the record is
    valid, the fault goes to ``stop_faults`` and is said and cleared, and the
    configuration keeps its figures."""
    st = ctl.status()
    if not st["faults"]:
        return
    if run is not None and run.get("stopped_by_host") and not run.get("faults_in_record", 1):
        if stop_faults is not None:
            stop_faults.append({"configuration": label, "faults": st["faults_names"]})
        say(f"{label}: the controller faulted ({', '.join(st['faults_names'])}) after the record, when the "
            "host stopped the wave: its figures stand; faults cleared")
    else:
        faulted.append({"configuration": label, "faults": st["faults_names"]})
        say(f"{label}: the controller faulted ({', '.join(st['faults_names'])}): its figures are invalid; "
            "faults cleared")
    ctl.arm(False)
    ctl.command("clear_faults")
    ctl.arm(True)


def _resonance(frf, tf) -> tuple[float, float]:
    """(identified resonance [Hz], the fit's natural frequency [Hz]).

    The resonance is the frequency of the largest measured magnitude
    (``feedback.resonance_hz``, 0.6 Hz lines on the SIL chirp); the notch, the
    shaper and the report use it. The second-order fit's natural frequency
    ``max |pole| / 2 pi`` is reported apart: a second-order model cannot hold
    the amplifier's pole and the tick's delay above the mode, so the fit trades
    the narrow peak for the broad band (941 Hz, damping 0.025 against the
    measured 970 Hz, 0.012 on the default stage, whose mode is 970 Hz).
    """
    from .feedback import resonance_hz
    poles = np.asarray(tf.poles)
    f_fit = float(np.max(np.abs(poles)) / (2 * np.pi)) if poles.size else float("nan")
    return resonance_hz(frf), f_fit


def calibrate(ctl, out: pathlib.Path, *, kinds=("eupi", "kp"), f_sweep: float = 1.0,
              target: dict | None = None, args=None) -> dict:
    """Calibrate the controller ``ctl`` and write ``out``/{model.json, table.bin, summary.json, report.html}.

    ``target`` (what ran: ``kind``, ``transport``, for QEMU ``image`` and
    ``image_sha256``) goes into the summary as it is. ``args`` (the command's
    namespace: ``quiet``, ``json``) decides whether progress is printed.
    Returns the summary (also written as ``summary.json``).
    """
    t_start = time.monotonic()
    out.mkdir(parents=True, exist_ok=True)
    data_dir = out / "data"
    data_dir.mkdir(exist_ok=True)
    sc = ctl.scale
    idn = ctl.identity
    steps = Steps(args)

    with steps.step(1, "connect") as row:
        st = ctl.status()
        ctl.arm(False)
        ctl.command("clear_faults")
        ctl.command("stop_wave")
        drive_path_raw(ctl)
        steps.result(row, f"axis {idn.axis + 1} of {idn.n_axes}, {idn.tick_hz} Hz, drive {sc.drive_min_v:g}.."
                          f"{sc.drive_max_v:g} V, position {sc.position_min_um:g}..{sc.position_max_um:g} um, "
                          f"active table {st['active_table_crc']:#010x}")

    with steps.step(2, "excitation (played and recorded by the firmware)") as row:
        ctl.set_mode("direct")
        ctl.arm(True)
        forc = excitation.forc_sweeps(ctl, f_hz=f_sweep, say=steps.say)
        files = []
        for k, r in enumerate(forc):
            path = data_dir / f"sweep_{k}.csv"
            save_recording(path, {"t": r["t"], "u": r["u"], "y": r["y"]},
                           meta={"source": "piezoctl calibrate", "top_fraction": r["top"]})
            files.append(str(path))
        steps.say("chirp 5..2000 Hz ...")
        ch = excitation.chirp(ctl)
        st = ctl.status()
        if st["faults"]:
            raise CliError(f"the controller faulted during the excitation: {', '.join(st['faults_names'])}")
        save_recording(data_dir / "chirp.csv", {"t": ch["t"], "u": ch["u"], "y": ch["y"]},
                       meta={"source": "piezoctl calibrate"})
        _park(ctl, -32768)
        y_lo, y_hi = float(np.min(forc[0]["y"])), float(np.max(forc[0]["y"]))
        steps.result(row, f"{len(forc)} nested sweeps at {f_sweep:g} Hz (stroke {y_hi - y_lo:.2f} um), "
                          f"chirp 5..2000 Hz: {sum(len(r['t']) for r in forc) + len(ch['t'])} samples recorded")

    with steps.step(3, "identify") as row:
        # each kind fitted without one sweep and tested on it; the best is fitted on all
        recs = [load_recording(f) for f in files]
        hold = len(files) // 2
        fit_idx = [i for i in range(len(files)) if i != hold]
        held = forc[hold]
        heldout = {}
        for kind in kinds:
            steps.say(f"{kind} on {len(fit_idx)} sweeps, tested on sweep {hold} ...")
            path = out / f"model_{kind}_heldout.json"
            fit_model(kind, [recs[i] for i in fit_idx], [files[i] for i in fit_idx], path, sc)
            m = load_model(path)
            heldout[kind] = _nrmse(held["y"], get_kind(kind).simulate(m.params, held["t"], held["u"]))
        chosen = min(heldout, key=heldout.get)
        steps.say(f"{chosen} on all {len(files)} sweeps ...")
        fit_model(chosen, recs, files, out / "model.json", sc)
        model = load_model(out / "model.json")
        params = dict(model.params)
        params["controller_scale"] = sc.to_dict()
        save_model(out / "model.json", chosen, params, model.provenance)
        model = load_model(out / "model.json")
        steps.say("dynamics: frequency response of the chirp, second-order fit ...")
        frf = excitation.chirp_frf(ch, fmin=5.0, fmax=2000.0, coherence_min=0.8)
        tf = tfid.fit_tf(frf, 2, method="pso-wcls")
        poles = np.asarray(tf.poles)
        f_res, f_fit = _resonance(frf, tf)
        steps.result(row, f"{chosen} (held-out NRMSE " + ", ".join(f"{k} {v:.4f}" for k, v in heldout.items())
                          + f"); resonance {f_res:.0f} Hz (measured peak; the 2nd-order fit's poles at "
                          f"{f_fit:.0f} Hz)")

    with steps.step(4, "checks before upload, feedback design") as row:
        steps.say("compile the model for the controller ...")
        try:
            comp = compile_model(model, sc)
        except TableImageError as exc:
            raise CliError(f"check refused the model: {exc}") from None
        steps.say("fixed-point inverse against float, forward(inverse) against identity ...")
        r_fs = 0.8 * np.sin(2 * np.pi * np.arange(20000) / 20000.0) * ((y_hi - y_lo) / (2 * sc.p_half))
        r_fs += (0.5 * (y_lo + y_hi) - sc.p_mid) / sc.p_half
        r_q15 = np.floor(r_fs * 32768 + 0.5).astype(np.int64)
        u_fix = np.asarray(comp.inverse_fixed(r_q15), dtype=np.float64)
        u_flt = np.asarray(comp.inverse_float(r_q15 / 32768.0)) * 32768.0
        quant_lsb = float(np.max(np.abs(u_fix - u_flt)))
        y_back = get_kind(chosen).simulate(model.params, np.arange(r_fs.size) * 1e-4,
                                           sc.drive_from_fs(u_fix / 32768.0))
        identity_err = float(np.max(np.abs(sc.position_to_fs(y_back) - r_fs)[2000:]) / np.ptp(r_fs))
        if identity_err > 0.05:
            raise CliError(f"forward-then-inverse differs from identity by {identity_err:.1%} of the range: "
                           "not uploading")
        steps.say("feedback design ...")
        fb = design_feedback(frf, comp.line[0], idn.tick_hz, f_res=f_res)
        steps.say("dynamics inverse: least-squares FIR on the measured response ...")
        dyn = design_dyninv(frf, idn.tick_hz, f_res, min_delay=fb["delay_ticks"], damping=fb["damping"],
                            shaper=(fb["preview_ticks"], fb["shaper_ticks"], fb["shaper_q15"]))
        info = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in comp.info.items())
        steps.result(row, f"{info}; forward(inverse) within {identity_err:.2%} of the range, fixed-point "
                          f"table within {quant_lsb:.1f} LSB of float; feedback: crossover "
                          f"{fb['crossover_hz']:.0f} Hz, notch and ZVD shaper at {fb['resonance_hz']:.0f} Hz "
                          f"(damping {fb['damping']:.3f}), preview {fb['preview_ticks']} ticks; dynamics inverse: "
                          f"{len(dyn.taps_q13)} taps every {dyn.spacing} tick(s), inverts "
                          f"{dyn.band_hz[0]:.0f}..{dyn.band_hz[1]:.0f} Hz, preview {dyn.preview_ticks} ticks, "
                          f"|H| <= {dyn.max_gain:.2f}, in-band error {dyn.inband_error:.3f} "
                          f"(preview and shaper {dyn.shaper_error:.3f})")

    with steps.step(5, "build and flash the table") as row:
        data = model.provenance.get("data", [])
        digest = hashlib.sha256("".join(d.get("sha256", "") for d in data).encode()).digest()
        img = build_image(comp.table_kind, comp.sections, table_version=int(time.time()),
                          fit_nrmse=heldout[chosen], build_time=int(time.time()), data_sha256=digest,
                          axis=ctl.identity.axis, drive_range_v=(sc.drive_min_v, sc.drive_max_v),
                          position_range_um=(sc.position_min_um, sc.position_max_um))
        (out / "table.bin").write_bytes(img)
        crc = flash_image(ctl, img, quiet=True)
        steps.result(row, f"table {comp.table_kind} ({len(img)} bytes, crc {crc:#010x}) staged, verified, "
                          "committed, active")

    with steps.step(6, "acceptance: triangles and a multitone, uncompensated and compensated") as row:
        centre, amp = 0.5 * (y_lo + y_hi), 0.4 * (y_hi - y_lo)
        runs = {}
        tracking = {}
        compensated = "ff_feedback"
        # a triangle well below the resonance only (its harmonics ring the mode: on a 140 Hz stage a
        # 100 Hz triangle uncompensated carries the stage out of its sensor's range)
        keys = [f for f in FREQS if f <= MAX_F_OF_RESONANCE * fb["resonance_hz"]] + ["multitone"]
        # what each part of the compensation buys: each configuration on every reference
        faulted = []   # configurations after whose runs the controller had faulted
        stop_faults = []   # faults latched only when the host stopped a multisine, after a valid record
        # the dynamics inverse runs before preview and shaper: the learning below starts from the
        # configuration the loop leaves loaded, preview and shaper
        configs = (("open_loop", "uncompensated", "open_loop", None),
                   ("feedback", "feedback only (PI + notch)", "feedback", None),
                   ("hysteresis", "+ hysteresis inverse", compensated, None),
                   (DYNINV, "+ dynamics inverse (preview, FIR)", compensated, "inverse"),
                   (compensated, "+ dynamics (preview, shaper)", compensated, "shaper"))
        label_of = {k: lab for k, lab, _, _ in configs}
        f_random = min(300.0, RANDOM_F_OF_RESONANCE * fb["resonance_hz"])
        for key_mode, label, mode, dynamics in configs:
            _park(ctl, ctl.q15_position(y_lo))
            if dynamics == "shaper":
                ctl.configure_shaper(fb["shaper_ticks"], fb["shaper_q15"], fb["preview_ticks"])
            elif dynamics == "inverse":   # instead of the shaper: the taps hold the mode's inverse
                ctl.configure_shaper(0, (32768, 0, 0), dyn.preview_ticks)
            else:
                ctl.configure_shaper()
            if dynamics == "inverse":
                ctl.configure_dyninv(dyn.taps_q13, dyn.spacing)
            else:
                ctl.configure_dyninv()
            if mode == "open_loop":
                ctl.configure_feedback()
            else:
                ctl.configure_feedback(kp=fb["kp"], ki=fb["ki"], notch=fb["notch"])
            ctl.set_mode(mode)
            st = ctl.status()
            if st["faults"]:
                raise CliError(f"the controller reports faults: {', '.join(st['faults_names'])}")
            ctl.arm(True)
            ilc.switch_off(ctl)
            # a fault is attributed to the reference whose run latched it: the others stay valid
            for f in keys[:-1]:
                if f < 10:   # the long one (3 s at 1 Hz): said on its own so the step is never silent long
                    steps.say(f"{label}: {f:g} Hz triangle ...")
                runs[(key_mode, f)] = excitation.triangle_run(ctl, f, centre, amp, periods=_periods(f))
                _recover(ctl, faulted, f"{label}, {f:g} Hz triangle", steps.say, runs[(key_mode, f)], stop_faults)
            steps.say(f"{label}: multitone ...")
            runs[(key_mode, "multitone")] = excitation.multitone_run(ctl, centre_um=centre, amp_um=amp)
            _recover(ctl, faulted, f"{label}, multitone", steps.say, runs[(key_mode, "multitone")], stop_faults)
            runs[(key_mode, RANDOM)] = excitation.random_scan_run(ctl, centre, amp, f_random)
            _recover(ctl, faulted, f"{label}, random scan", steps.say, runs[(key_mode, RANDOM)], stop_faults)
        # + the learned feedforward: trials on the controller, then the same measurement with it played
        learned = {}
        f_cut_max = ILC_F_CUT * fb["resonance_hz"]
        # the learning starts from the full configuration, unless that one faulted the controller (the
        # 140 Hz stage's 50 Hz triangle with preview and shaper, sometimes): then from the one before it
        learn_base = compensated
        if any(f["configuration"].startswith(label_of[compensated] + ",") for f in faulted):
            learn_base = "hysteresis"
            steps.say("learned feedforward: from the hysteresis inverse and feedback (preview and shaper "
                      "faulted the controller)")
            _park(ctl, ctl.q15_position(y_lo))
            ctl.configure_shaper()
            ctl.configure_feedback(kp=fb["kp"], ki=fb["ki"], notch=fb["notch"])
            ctl.set_mode(compensated)
            ctl.arm(True)
        for key in keys:
            f0 = key if key != "multitone" else min(excitation.MULTITONE_HZ)
            if key == "multitone":
                excitation.load_multitone(ctl, centre_um=centre, amp_um=amp)
            else:
                excitation.load_triangle(ctl, key, centre, amp)
            name = f"{key:g} Hz triangle" if key != "multitone" else "multitone"
            trials = ILC_TRIALS["slow" if f0 < 10 else "fast"]
            steps.say(f"learned feedforward: {name}, {trials} trials ...")
            res = ilc.learn_on_controller(ctl, f0, preview_ticks=fb["preview_ticks"] if learn_base == compensated
                                          else 0,
                                          f_cut_hz=f_cut_max, iterations=trials,
                                          periods=1 if f0 < 10 else _periods(f0))
            learned[key] = res
            if key == "multitone":
                runs[(LEARNED, key)] = excitation.multitone_run(ctl, centre_um=centre, amp_um=amp)
            else:
                runs[(LEARNED, key)] = excitation.triangle_run(ctl, key, centre, amp, periods=_periods(key))
            ilc.switch_off(ctl)
            _recover(ctl, faulted, f"+ learned feedforward, {name}", steps.say, runs[(LEARNED, key)], stop_faults)
        _park(ctl, ctl.q15_position(y_lo))
        bad = {f["configuration"] for f in faulted}
        for key in keys:
            rms = {k: _rms(runs[(k, key)]["ref"] - runs[(k, key)]["y"])
                   for k in ("open_loop", "feedback", "hysteresis", DYNINV, compensated, LEARNED)}
            name = f"{key:g}" if key != "multitone" else "multitone"
            # the compensation this reference gets: the learned feedforward unless its run faulted the
            # controller (its figures are invalid: the 140 Hz stage's 50 Hz triangle, sometimes), then the
            # model-based configurations in turn
            label = f"{key:g} Hz triangle" if key != "multitone" else "multitone"
            # of the two model-based dynamics parts, the better one on this reference (the other is said)
            model_based = sorted((compensated, DYNINV), key=lambda k: rms[k])
            chain = ((LEARNED, f"+ learned feedforward, {label}"),
                     *((k, label_of[k]) for k in model_based),
                     ("hysteresis", label_of["hysteresis"]), ("feedback", label_of["feedback"]))
            used = next((k for k, lab in chain if lab not in bad and f"{lab}, {label}" not in bad), "feedback")
            unc, com = rms["open_loop"], rms[used]
            res = learned[key]
            tracking[name] = {"rmse_uncompensated_um": unc, "rmse_compensated_um": com,
                              "reduction": unc / com if com > 0 else float("inf"),
                              "compensation_used": "learned" if used == LEARNED else used,
                              "dynamics_inverse_vs_shaper": rms[DYNINV] / rms[compensated]
                              if rms[compensated] > 0 else float("inf"),
                              "rmse_by_part_um": {"feedback": rms["feedback"], "hysteresis": rms["hysteresis"],
                                                  "dynamics": rms[compensated], DYNINV: rms[DYNINV],
                                                  "learned": com},
                              "learned": {"trials": len(res["history"]), "refused": res["refused"],
                                          "base": learn_base,
                                          "trial_rms_um": [h["rms_um"] for h in res["history"]],
                                          "trial_rms_all_um": res["rms_all_um"],
                                          "lag_s": res["lag_s"], "f_cut_hz": res["f_cut_hz"],
                                          "entries": res["n_entries"]}}
        # the reference not known in advance: no learning, each configuration as it is
        rnd = {k: _rms(runs[(k, RANDOM)]["ref"] - runs[(k, RANDOM)]["y"]) for k, _, _, _ in configs}
        rnd_bad = {k for k, lab, _, _ in configs if f"{lab}, random scan" in bad}
        tones = excitation.random_scan_tones(f_random)
        random_scan = {"tones_hz": [round(f, 3) for f, _ in tones], "band_hz": [excitation.RANDOM_SCAN_F_LO, f_random],
                       "window_s": excitation.RANDOM_SCAN_WINDOW_S, "seed": excitation.RANDOM_SCAN_SEED,
                       "rmse_by_part_um": {"uncompensated" if k == "open_loop" else
                                           ("dynamics" if k == compensated else k): v for k, v in rnd.items()},
                       "faulted": sorted("uncompensated" if k == "open_loop" else
                                         ("dynamics" if k == compensated else k) for k in rnd_bad),
                       "dynamics_inverse_vs_shaper": rnd[DYNINV] / rnd[compensated]
                       if rnd[compensated] > 0 else float("inf")}
        worse_inverse = [k for k, v in tracking.items() if v["dynamics_inverse_vs_shaper"] > 1.0]
        if random_scan["dynamics_inverse_vs_shaper"] > 1.0:
            worse_inverse.append("random scan")
        text_inverse = (f"; random scan (not learned, {excitation.RANDOM_SCAN_F_LO:g}..{f_random:.0f} Hz) "
                        f"{rnd['open_loop']:.3f} -> {rnd[compensated]:.3f} um with preview and shaper, "
                        f"{rnd[DYNINV]:.3f} um with the dynamics inverse"
                        + (f"; the dynamics inverse is worse than preview and shaper on: {', '.join(worse_inverse)}"
                           if worse_inverse else ""))
        if faulted:
            text_faults = "; faulted: " + ", ".join(f["configuration"] for f in faulted)
        else:
            text_faults = ""
        worse = [k for k, v in tracking.items() if v["rmse_compensated_um"] > v["rmse_uncompensated_um"]]
        rolled_back = False
        rollback_result = None
        text = "; ".join(f"{k} Hz {v['rmse_uncompensated_um']:.3f} -> {v['rmse_compensated_um']:.3f} um "
                         f"({v['reduction']:.1f}x)" if k != "multitone" else
                         f"multitone {v['rmse_uncompensated_um']:.3f} -> {v['rmse_compensated_um']:.3f} um "
                         f"({v['reduction']:.1f}x)" for k, v in tracking.items()) + text_inverse + text_faults
        if worse:
            rollback_result = ctl.rollback_table()
            rolled_back = rollback_result == "ok"
            text += (f"; compensation made {', '.join(worse)} worse: "
                     + ("rolled back to the previous table" if rolled_back else
                        f"rollback refused ({rollback_result}): the new table stays active"))
        # the accepted feedback, notch and shaper persist across a restart: the controller's parameter
        # record (A/B flash with a CRC, docs/operate.md), saved disarmed with the compensated settings loaded
        params_saved = None
        if not rolled_back:
            ctl.configure_dyninv()
            ctl.configure_shaper(fb["shaper_ticks"], fb["shaper_q15"], fb["preview_ticks"])
            ctl.configure_feedback(kp=fb["kp"], ki=fb["ki"], notch=fb["notch"])
            was_armed = bool(ctl.status()["armed"])
            ctl.arm(False)
            params_saved = ctl.params_command("save")
            if was_armed:   # as the acceptance left it (a second axis is calibrated next to this one)
                ctl.arm(True)
            text += ("; feedback, notch and shaper saved in the controller's flash" if params_saved == "ok" else
                     f"; saving the parameters was refused ({params_saved}): they are lost at a restart")
        steps.result(row, text)

    with steps.step(7, "report") as row:
        summary = {
            "tool_version": __version__,
            "model": chosen,
            "table_kind": comp.table_kind,
            "heldout_nrmse": heldout[chosen],
            "heldout_nrmse_by_model": heldout,
            "table_crc": crc,
            "table_crc_hex": f"{crc:#010x}",
            "rolled_back": rolled_back,
            "worse_than_uncompensated": worse,
            "rollback_result": rollback_result,
            "params_saved": params_saved,
            "tracking": tracking,
            "acceptance_faults": faulted,
            "acceptance_stop_faults": stop_faults,
            "random_scan": random_scan,
            "dynamics_inverse_worse_on": worse_inverse,
            "checks": {"forward_inverse_max_error_fraction": identity_err, "quantization_max_lsb": quant_lsb,
                       **{k: v for k, v in comp.info.items() if isinstance(v, (int, float))}},
            "compensation": {"mode": compensated, "preview_ticks": fb["preview_ticks"], "kp": fb["kp"],
                             "ki_per_tick": fb["ki"], "crossover_hz": fb["crossover_hz"],
                             "notch_hz": fb["resonance_hz"], "damping": fb["damping"],
                             "shaper_ticks": fb["shaper_ticks"], "shaper_q15": fb["shaper_q15"],
                             "dynamics_inverse": dyn.to_dict()},
            "dynamics": {"num": list(map(float, tf.num)), "den": list(map(float, tf.den)),
                         "poles": [[float(p.real), float(p.imag)] for p in poles], "te": float(tf.te),
                         "resonance_hz": f_res, "resonance_source": "frequency of the largest magnitude of the "
                                                                    "measured frequency response (chirp)",
                         "fit_natural_hz": f_fit, "damping": fb["damping"]},
            "stroke_um": y_hi - y_lo,
            "scale": sc.to_dict(),
            "files": {"model": "model.json", "table": "table.bin", "report": "report.html", "data": "data/"},
            "duration_s": None,
            "target": target,
            "steps": steps.rows,
        }
        from .report import write_report
        summary["duration_s"] = time.monotonic() - t_start
        # the report's own row: its duration so far (the figures are most of it)
        row["result"] = f"{out / 'report.html'}"
        write_report(out / "report.html", summary, forc=forc, model=model, frf=frf, tf=tf, runs=runs, img=img,
                     compensated=LEARNED, steps=steps.rows + [row], say=steps.say)
        summary["duration_s"] = time.monotonic() - t_start
        steps.result(row, f"{out / 'report.html'} ({summary['duration_s']:.0f} s in all)")
    (out / "summary.json").write_text(json.dumps(summary, indent=2, sort_keys=True))
    return summary
