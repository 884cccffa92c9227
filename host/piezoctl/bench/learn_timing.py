"""The two-axis SIL stage's 50 Hz learning under host and controller delays (round 18).

``tools/bench-learn-timing --cal DIR`` takes a two-axis calibration's axis 1
(``DIR/summary.json``, ``DIR/table.bin``, its first sweep for the stroke), starts a
fresh two-axis SIL controller with that table and the calibration's feedback,
preview and shaper, and per repetition plays what calibrate's step 6 does for the
50 Hz triangle: the compensated run, the learning (10 trials,
:func:`piezoctl.calibrate.ilc.learn_on_controller`) and the learned run. It prints
one JSON line per repetition (RMS errors [um], the reduction against the
calibration's uncompensated figure, the learning's trials, ``lag_s``, ``refused``,
``records_repeated``, the duplicated replies the transport skipped) and the
controller's pacing statistics.

Disturbances, each optional:

- ``--delay-ms D``: the host sleeps a uniform 0..D ms before every request (a slow host);
- ``--stall-s S``: the controller process is stopped (SIGSTOP) for S s every 1-4 s
  (a controller that answers late);
- ``--duplicate-start-ms D``: on odd repetitions the first record's ``start_wave``
  is sent once more D ms later (what a transport that re-sends a request does).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import pathlib
import random
import signal
import threading
import time

import numpy as np

__all__ = ["main"]

F_HZ = 50.0
TRIALS = 10


class _Skipped(logging.Handler):
    """Counts pymodbus' "Skipping" errors: a reply whose transaction id is not the
    request's, i.e. the second reply to a request the controller received twice."""

    def __init__(self):
        super().__init__(logging.ERROR)
        self.count = 0

    def emit(self, record):
        if "Skipping" in record.getMessage():
            self.count += 1


def _stall(proc, seconds: float, seed: int) -> None:
    rng = random.Random(seed)
    while proc.poll() is None:
        time.sleep(rng.uniform(1.0, 4.0))
        if proc.poll() is not None:
            return
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(proc.pid, signal.SIGCONT)


def main(argv=None) -> int:
    """Run the benchmark; returns the exit status."""
    from ..calibrate import excitation, ilc
    from ..calibrate.feedback import notch
    from ..calibrate.pipeline import _park, _periods
    from ..commands.flash import flash_image
    from ..device import connect
    from ..io.recording import load_recording
    from ..sil.launch import VirtualController
    from ..sil.stage import default_stage_path

    ap = argparse.ArgumentParser(prog="bench-learn-timing", description=__doc__.split("\n\n")[0])
    ap.add_argument("--cal", required=True, type=pathlib.Path, help="a two-axis calibration's DIR (axis 1)")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--delay-ms", type=float, default=0.0)
    ap.add_argument("--stall-s", type=float, default=0.0)
    ap.add_argument("--duplicate-start-ms", type=float, default=-1.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    s = json.loads((a.cal / "summary.json").read_text())
    comp = s["compensation"]
    y = load_recording(a.cal / s["files"]["data"] / "sweep_0.csv").y
    y_lo, y_hi = float(np.min(y)), float(np.max(y))
    centre, amp = 0.5 * (y_lo + y_hi), 0.4 * (y_hi - y_lo)   # calibrate's step 6
    unc = s["tracking"]["50"]["rmse_uncompensated_um"]
    skipped = _Skipped()
    logging.getLogger("pymodbus").addHandler(skipped)
    rng = random.Random(a.seed)
    vc = VirtualController(stage=default_stage_path("two_axis"), seed=1).start()
    try:
        ctl = connect(vc.port)
        if a.delay_ms > 0:
            for name in ("_read", "_write", "_read_write"):
                def slow(*args, _f=getattr(ctl.client, name), **kw):
                    time.sleep(rng.uniform(0.0, a.delay_ms) / 1000.0)
                    return _f(*args, **kw)
                setattr(ctl.client, name, slow)
        if a.stall_s > 0:
            threading.Thread(target=_stall, args=(vc.proc, a.stall_s, a.seed), daemon=True).start()
        ctl.arm(False)
        ctl.command("clear_faults")
        flash_image(ctl, (a.cal / "table.bin").read_bytes(), quiet=True)
        tick = ctl.identity.tick_hz
        command = ctl.command
        for rep in range(a.reps):
            _park(ctl, ctl.q15_position(y_lo))
            ctl.configure_shaper(comp["shaper_ticks"], comp["shaper_q15"], comp["preview_ticks"])
            ctl.configure_dyninv()
            ctl.configure_feedback(kp=comp["kp"], ki=comp["ki_per_tick"], notch=notch(comp["notch_hz"], tick))
            ctl.set_mode(comp["mode"])
            ctl.arm(True)
            ilc.switch_off(ctl)
            run = excitation.triangle_run(ctl, F_HZ, centre, amp, periods=_periods(F_HZ))
            e_comp = float(np.sqrt(np.mean((run["ref"] - run["y"]) ** 2)))
            excitation.load_triangle(ctl, F_HZ, centre, amp)
            once = [a.duplicate_start_ms >= 0 and rep % 2 == 1]

            def twice(name):
                command(name)
                if name == "start_wave" and once[0]:
                    once[0] = False
                    time.sleep(a.duplicate_start_ms / 1000.0)
                    command(name)
            ctl.command = twice
            n0 = skipped.count
            res = ilc.learn_on_controller(ctl, F_HZ, preview_ticks=comp["preview_ticks"],
                                          f_cut_hz=2.0 * comp["notch_hz"], iterations=TRIALS,
                                          periods=_periods(F_HZ))
            ctl.command = command
            run = excitation.triangle_run(ctl, F_HZ, centre, amp, periods=_periods(F_HZ))
            ilc.switch_off(ctl)
            e = float(np.sqrt(np.mean((run["ref"] - run["y"]) ** 2)))
            st = ctl.status()
            print(json.dumps({"rep": rep, "compensated_um": round(e_comp, 4), "learned_um": round(e, 4),
                              "reduction": round(unc / e, 2), "lag_s": round(res["lag_s"], 6),
                              "refused": res["refused"], "records_repeated": res.get("records_repeated"),
                              "trials_um": [round(h["rms_um"], 3) for h in res["history"]],
                              "duplicate_replies": skipped.count - n0, "faults": st["faults"]}), flush=True)
            if st["faults"]:
                ctl.arm(False)
                ctl.command("clear_faults")
    finally:
        vc.stop()
        print(vc.stats, flush=True)
    return 0
