"""The seven steps of ``piezoctl calibrate`` (see ``docs/calibrate.md``)."""

from __future__ import annotations

import contextlib
import io
import json
import pathlib
import sys
import time
import zlib

import numpy as np

from .. import __version__
from ..commands.flash import flash_image
from ..errors import CliError
from ..ident import get_kind
from ..ident import tf as tfid
from ..io.modelfile import load_model, save_model
from ..io.recording import save_recording
from ..tables.from_model import compile_model
from ..tables.image import TableImageError, build_image
from . import excitation
from .feedback import design_feedback

__all__ = ["calibrate"]

STEPS = 7
FREQS = (1.0, 10.0, 50.0)


def _log(n: int, text: str) -> None:
    print(f"[{n}/{STEPS}] {text}", file=sys.stderr, flush=True)


def _identify(kind: str, files: list[str], out: str, scale) -> tuple[float, str]:
    """Run ``piezoctl identify`` for ``kind`` (drive normalized to the controller's range)."""
    from .. import cli
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli.main(["identify", "--model", kind, "--data", *files, "--out", out,
                       "--u-range", f"{scale.drive_min_v:.9g}", f"{scale.drive_max_v:.9g}"])
    if rc != 0:
        raise CliError(f"identify --model {kind} failed")
    return 0.0, buf.getvalue()


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


def calibrate(ctl, out: pathlib.Path, *, kinds=("eupi", "kp"), f_sweep: float = 1.0,
              target: dict | None = None) -> dict:
    """Calibrate the controller ``ctl`` and write ``out``/{model.json, table.bin, summary.json, report.html}.

    ``target`` (what ran: ``kind``, ``transport``, for QEMU ``image`` and
    ``image_sha256``) goes into the summary as it is.
    Returns the summary (also written as ``summary.json``).
    """
    t_start = time.monotonic()
    out.mkdir(parents=True, exist_ok=True)
    data_dir = out / "data"
    data_dir.mkdir(exist_ok=True)
    sc = ctl.scale
    idn = ctl.identity
    report: dict = {"steps": []}

    # 1. connect
    st = ctl.status()
    _log(1, f"connected: axis {idn.axis + 1} of {idn.n_axes}, {idn.tick_hz} Hz, drive {sc.drive_min_v:g}..{sc.drive_max_v:g} V, "
            f"position {sc.position_min_um:g}..{sc.position_max_um:g} um, active table {st['active_table_crc']:#010x}")
    ctl.arm(False)
    ctl.command("clear_faults")
    ctl.command("stop_wave")

    # 2. excitation, played and recorded by the firmware
    ctl.set_mode("direct")
    ctl.arm(True)
    forc = excitation.forc_sweeps(ctl, f_hz=f_sweep)
    files = []
    for k, r in enumerate(forc):
        path = data_dir / f"sweep_{k}.csv"
        save_recording(path, {"t": r["t"], "u": r["u"], "y": r["y"]},
                       meta={"source": "piezoctl calibrate", "top_fraction": r["top"]})
        files.append(str(path))
    ch = excitation.chirp(ctl)
    st = ctl.status()
    if st["faults"]:
        raise CliError(f"the controller faulted during the excitation: {', '.join(st['faults_names'])}")
    save_recording(data_dir / "chirp.csv", {"t": ch["t"], "u": ch["u"], "y": ch["y"]},
                   meta={"source": "piezoctl calibrate"})
    _park(ctl, -32768)
    y_lo, y_hi = float(np.min(forc[0]["y"])), float(np.max(forc[0]["y"]))
    _log(2, f"excitation: {len(forc)} nested sweeps at {f_sweep:g} Hz (stroke {y_hi - y_lo:.2f} um), "
            f"chirp 5..2000 Hz: {sum(len(r['t']) for r in forc) + len(ch['t'])} samples recorded")

    # 3. identify: each kind fitted without one sweep and tested on it; the best is fitted on all
    hold = len(files) // 2
    fit_files = [f for i, f in enumerate(files) if i != hold]
    held = forc[hold]
    heldout = {}
    for kind in kinds:
        path = out / f"model_{kind}_heldout.json"
        _identify(kind, fit_files, str(path), sc)
        m = load_model(path)
        heldout[kind] = _nrmse(held["y"], get_kind(kind).simulate(m.params, held["t"], held["u"]))
    chosen = min(heldout, key=heldout.get)
    _identify(chosen, files, str(out / "model.json"), sc)
    model = load_model(out / "model.json")
    params = dict(model.params)
    params["controller_scale"] = sc.to_dict()
    save_model(out / "model.json", chosen, params, model.provenance)
    model = load_model(out / "model.json")
    frf = excitation.chirp_frf(ch, fmin=5.0, fmax=2000.0, coherence_min=0.8)
    tf = tfid.fit_tf(frf, 2, method="pso-wcls")
    poles = np.asarray(tf.poles)
    f_res = float(np.max(np.abs(poles)) / (2 * np.pi)) if poles.size else float("nan")
    _log(3, f"identified: {chosen} (held-out NRMSE " + ", ".join(f"{k} {v:.4f}" for k, v in heldout.items())
            + f"); dynamics: 2nd order, resonance {f_res:.0f} Hz")

    # 4. checks before upload
    try:
        comp = compile_model(model, sc)
    except TableImageError as exc:
        raise CliError(f"check refused the model: {exc}") from None
    r_fs = 0.8 * np.sin(2 * np.pi * np.arange(20000) / 20000.0) * ((y_hi - y_lo) / (2 * sc.p_half))
    r_fs += (0.5 * (y_lo + y_hi) - sc.p_mid) / sc.p_half
    r_q15 = np.floor(r_fs * 32768 + 0.5).astype(np.int64)
    u_fix = np.asarray(comp.inverse_fixed(r_q15), dtype=np.float64)
    u_flt = np.asarray(comp.inverse_float(r_q15 / 32768.0)) * 32768.0
    quant_lsb = float(np.max(np.abs(u_fix - u_flt)))
    y_back = get_kind(chosen).simulate(model.params, np.arange(r_fs.size) * 1e-4, sc.drive_from_fs(u_fix / 32768.0))
    identity_err = float(np.max(np.abs(sc.position_to_fs(y_back) - r_fs)[2000:]) / np.ptp(r_fs))
    if identity_err > 0.05:
        raise CliError(f"forward-then-inverse differs from identity by {identity_err:.1%} of the range: not uploading")
    fb = design_feedback(frf, comp.line[0], idn.tick_hz)
    _log(4, f"checks: {comp.info}, forward(inverse) within {identity_err:.2%} of the range, "
            f"fixed-point table within {quant_lsb:.1f} LSB of float; feedback: crossover {fb['crossover_hz']:.0f} Hz, "
            f"notch and ZVD shaper at {fb['resonance_hz']:.0f} Hz (damping {fb['damping']:.3f}), "
            f"preview {fb['preview_ticks']} ticks")

    # 5. build, flash
    data = model.provenance.get("data", [])
    digest = __import__("hashlib").sha256("".join(d.get("sha256", "") for d in data).encode()).digest()
    img = build_image(comp.table_kind, comp.sections, table_version=int(time.time()),
                      fit_nrmse=heldout[chosen], build_time=int(time.time()), data_sha256=digest,
                      axis=ctl.identity.axis, drive_range_v=(sc.drive_min_v, sc.drive_max_v),
                      position_range_um=(sc.position_min_um, sc.position_max_um))
    (out / "table.bin").write_bytes(img)
    crc = flash_image(ctl, img, quiet=True)
    _log(5, f"table {comp.table_kind} ({len(img)} bytes, crc {crc:#010x}) staged, verified, committed, active")

    # 6. acceptance: triangles and a multitone, uncompensated and compensated
    centre, amp = 0.5 * (y_lo + y_hi), 0.4 * (y_hi - y_lo)
    runs = {}
    tracking = {}
    compensated = "ff_feedback"
    for mode in ("open_loop", compensated):
        _park(ctl, ctl.q15_position(y_lo))
        if mode == "open_loop":
            ctl.configure_shaper()
            ctl.configure_feedback()
        else:
            ctl.configure_shaper(fb["shaper_ticks"], fb["shaper_q15"], fb["preview_ticks"])
            ctl.configure_feedback(kp=fb["kp"], ki=fb["ki"], notch=fb["notch"])
        ctl.set_mode(mode)
        st = ctl.status()
        if st["faults"]:
            raise CliError(f"the controller reports faults: {', '.join(st['faults_names'])}")
        ctl.arm(True)
        for f in FREQS:
            runs[(mode, f)] = excitation.triangle_run(ctl, f, centre, amp, periods=2 if f < 10 else 5)
        runs[(mode, "multitone")] = excitation.multitone_run(ctl, centre_um=centre, amp_um=amp)
    _park(ctl, ctl.q15_position(y_lo))
    for key in list(FREQS) + ["multitone"]:
        unc = _rms(runs[("open_loop", key)]["ref"] - runs[("open_loop", key)]["y"])
        com = _rms(runs[(compensated, key)]["ref"] - runs[(compensated, key)]["y"])
        name = f"{key:g}" if key != "multitone" else "multitone"
        tracking[name] = {"rmse_uncompensated_um": unc, "rmse_compensated_um": com,
                          "reduction": unc / com if com > 0 else float("inf")}
    worse = [k for k, v in tracking.items() if v["rmse_compensated_um"] > v["rmse_uncompensated_um"]]
    rolled_back = False
    rollback_result = None
    if worse:
        rollback_result = ctl.rollback_table()
        rolled_back = rollback_result == "ok"
        _log(6, f"compensation made {', '.join(worse)} worse: "
                + ("rolled back to the previous table" if rolled_back else
                   f"rollback refused ({rollback_result}): the new table stays active"))
    _log(6, "acceptance: " + ", ".join(f"{k} Hz {v['rmse_uncompensated_um']:.3f} -> {v['rmse_compensated_um']:.3f} um "
                                       f"({v['reduction']:.1f}x)" if k != "multitone" else
                                       f"multitone {v['rmse_uncompensated_um']:.3f} -> {v['rmse_compensated_um']:.3f} um"
                                       for k, v in tracking.items()))

    # 7. report
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
        "tracking": tracking,
        "checks": {"forward_inverse_max_error_fraction": identity_err, "quantization_max_lsb": quant_lsb,
                   **{k: v for k, v in comp.info.items() if isinstance(v, (int, float))}},
        "compensation": {"mode": compensated, "preview_ticks": fb["preview_ticks"], "kp": fb["kp"], "ki_per_tick": fb["ki"],
                         "crossover_hz": fb["crossover_hz"], "notch_hz": fb["resonance_hz"], "damping": fb["damping"],
                         "shaper_ticks": fb["shaper_ticks"], "shaper_q15": fb["shaper_q15"]},
        "dynamics": {"num": list(map(float, tf.num)), "den": list(map(float, tf.den)),
                     "poles": [[float(p.real), float(p.imag)] for p in poles], "te": float(tf.te),
                     "resonance_hz": f_res},
        "stroke_um": y_hi - y_lo,
        "scale": sc.to_dict(),
        "files": {"model": "model.json", "table": "table.bin", "report": "report.html", "data": "data/"},
        "duration_s": None,
        "target": target,
    }
    from .report import write_report
    summary["duration_s"] = time.monotonic() - t_start
    write_report(out / "report.html", summary, forc=forc, model=model, frf=frf, tf=tf, runs=runs, img=img,
                 compensated=compensated)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, sort_keys=True))
    _log(7, f"report: {out / 'report.html'} ({summary['duration_s']:.0f} s)")
    return summary
