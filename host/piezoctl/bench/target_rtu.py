"""The worst tick of the firmware image while its Modbus RTU server is busy
(``tools/bench-target``, docs/target-cortex-m4.md).

The PIL image (the firmware's main, control loop and RTU server; the C stage
model behind the converter seams, in PendSV, outside the tick) runs under
QEMU with ``-icount shift=0``: one instruction is one nanosecond of emulated
time, so the firmware's own tick-time register (``tick_time_max_ns``: from the
instant a tick was due to the end of its work, SysTick's counter) counts
instructions and latency exactly, whatever this machine's load. The host
drives the server through phases, each a kind of request, with the stage
moving (DIRECT mode, 50 Hz triangle); after each phase the maximum so far
tells which phase set it.
"""

from __future__ import annotations

import time

from ..calibrate.target import QemuTarget
from ..commands.flash import flash_image
from ..errors import CliError
from ..device import connect
from ..calibrate.feedback import notch
from ..fixtures.ctl import dcc_image, eupi_image

__all__ = ["busy_tick"]


def busy_tick(image: str | None = None, icount: str = "shift=0,sleep=off", reps: int = 20,
              mode: str = "ff_feedback") -> dict:
    """Run the phases; returns ``{"phases": [(name, requests, tick_time_max_ns)], "image": ...}``."""
    phases = []
    with QemuTarget(image=image, icount=icount) as q:
        # under sleep=off a request delayed on this host can reach the
        # firmware as two frames (emulated time jumps while it waits): the
        # first identity read is retried, a dropped request later fails the run
        for attempt in range(3):
            try:
                ctl = connect(q.port, timeout=10.0)
                break
            except CliError:
                if attempt == 2:
                    raise

        def mark(name: str, requests: int) -> None:
            phases.append((name, requests, ctl.status()["tick_time_max_ns"]))

        for _ in range(20):
            ctl.status()
        mark("status reads, idle", 20)
        ctl.arm(False)
        ctl.command("clear_faults")
        imgs = (("kp_dcc", dcc_image()[0]), ("eupi_inverse", eupi_image()[0]))
        if mode == "ff_feedback":
            flash_image(ctl, imgs[1][1], quiet=True)
            mark("one table flashed (eupi_inverse: upload, read-back, commit)", 10)
        ctl.unlock()
        for _ in range(reps):
            ctl.configure_feedback(kp=0.28, ki=0.107, notch=notch(969.0, 10000))
        mark(f"feedback configuration (FC 16), x {reps}", 3 * reps)
        ctl.set_mode(mode)
        ctl.configure_wave("triangle", offset_q15=-4000, amplitude_q15=10000, f_hz=50.0)
        ctl.arm(True)
        ctl.command("start_wave")
        for _ in range(100):
            ctl.status()
        mark(f"status reads, {mode} with the table, PI + notch, 50 Hz triangle, x 100", 100)
        ctl.capture(["ref", "y"], ctl.identity.rec_capacity // 2, trigger="immediate")
        mark("recorder: capture and readout of 8192 samples (FC 23), same", 70)
        for k in range(reps):
            name, img = imgs[k % 2]
            ctl.upload_table(img)
            ctl.read_staged(len(img))
        mark(f"table upload (FC 16) and read-back (FC 23) while armed, x {reps}", reps * 8)
        st = ctl.status()
        mark(f"(still armed: {bool(st['armed'])}, faults {st['faults_names']})", 1)
        ctl.command("stop_wave")
        ctl.arm(False)
        for k in range(reps):
            name, img = imgs[k % 2]
            flash_image(ctl, img, quiet=True)
        mark(f"table commits (persisted to the image's storage), alternating kinds, x {reps}", reps * 10)
        for _ in range(reps):
            res = ctl.rollback_table()
        mark(f"table rollbacks, x {reps}: last {res}", reps)
        for _ in range(100):
            ctl.status()
        mark("status reads, after", 100)
    return {"phases": phases, "image": q.describe()}


def main() -> int:
    # feedback (PI + notch, no table): the maximum is not set by a commit
    # before the serving phases; ff_feedback flashes a table first, so its
    # maximum includes one commit
    for mode in ("feedback", "ff_feedback"):
        r = busy_tick(mode=mode)
        # the maximum is monotonic: its value before the first commit phase
        serving = next(p[2] for p in r["phases"] if p[0].startswith("(still armed"))
        worst = max(p[2] for p in r["phases"])
        print(f"worst_tick_busy_ns ({mode}): {serving} while serving reads, uploads, read-backs and "
              f"configuration{' (after one commit)' if mode == 'ff_feedback' else ''}; "
              f"{worst} with table commits and rollbacks (tick period 100000 ns; "
              f"PIL image sha256 {r['image']['image_sha256'][:16]})")
        for name, _req, ns in r["phases"]:
            print(f"  after {name}: tick_time_max_ns {ns}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
