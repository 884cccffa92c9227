"""How long ``piezoctl calibrate`` takes, end to end, against its goals.

Each target runs once, in a fresh output directory, as a user would run it:

- ``sil``: ``calibrate --target sil`` (the default stage, both candidate
  models); goal 120 s.
- ``qemu``: ``calibrate --target qemu --models eupi`` (the PIL image under
  QEMU, Modbus RTU); goal 300 s. QEMU runs with ``-icount``: the controller's
  clock is counted in instructions, so on a loaded host it ticks slower than
  real time (the calibration's waits are counted in its ticks: device.py
  ``wait_recorder``); this bench also prints the ticks per wall second.
- ``two-axis``: ``calibrate --target sil --stage two_axis``; goal 420 s.

Printed per target: wall seconds, the summary's ``duration_s``, the goal,
``ok``/``over``; and the machine's load average at start and end (a wall time
on a shared machine is an upper bound). The tests check what the calibration
achieves, not how long it took: that is measured here (README "Standards").

    tools/bench-calibrate [--targets sil,qemu,two-axis] [--keep DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import pathlib
import tempfile
import time

GOALS_S = {"sil": 120.0, "qemu": 300.0, "two-axis": 420.0}


def _args(target: str, out: pathlib.Path) -> list[str]:
    if target == "sil":
        return ["calibrate", "--target", "sil", "--out", str(out)]
    if target == "qemu":
        return ["calibrate", "--target", "qemu", "--models", "eupi", "--out", str(out)]
    from ..sil.stage import default_stage_path
    return ["calibrate", "--target", "sil", "--stage", str(default_stage_path("two_axis")), "--out", str(out)]


def qemu_ticks_per_second(seconds: float = 3.0) -> float:
    """Ticks per wall second of the PIL image under QEMU, idle (10000 in real time)."""
    from ..calibrate.target import QemuTarget
    from ..device import connect
    with QemuTarget() as q:
        ctl = connect(q.port, timeout=5.0)
        t0, c0 = time.monotonic(), ctl.status()["tick_count"]
        time.sleep(seconds)
        t1, c1 = time.monotonic(), ctl.status()["tick_count"]
    return ((c1 - c0) % (1 << 32)) / (t1 - t0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tools/bench-calibrate", description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets", default="sil,qemu", help="comma list of sil, qemu, two-axis (default sil,qemu)")
    ap.add_argument("--keep", default=None, help="keep each calibration's output in DIR/TARGET")
    a = ap.parse_args(argv)
    targets = a.targets.split(",")
    bad = [t for t in targets if t not in GOALS_S]
    if bad:
        ap.error(f"unknown target(s) {', '.join(bad)}: choose from {', '.join(GOALS_S)}")
    from .. import cli
    root = pathlib.Path(a.keep or tempfile.mkdtemp(prefix="bench-calibrate-"))
    root.mkdir(parents=True, exist_ok=True)
    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    rc_all = 0
    for target in targets:
        if target == "qemu":
            print(f"qemu: PIL image idle, {qemu_ticks_per_second():.0f} ticks per wall second "
                  f"(10000 in real time)", flush=True)
        out = root / target
        t0 = time.monotonic()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            rc = cli.main(_args(target, out))
        wall = time.monotonic() - t0
        summ = out / "summary.json"
        dur = json.loads(summ.read_text()).get("duration_s") if summ.exists() else None
        verdict = "ok" if rc == 0 and wall <= GOALS_S[target] else ("failed" if rc != 0 else "over")
        rc_all = rc_all or rc
        print(f"{target}: {wall:.1f} s wall, duration_s {dur if dur is None else round(dur, 1)}, "
              f"goal {GOALS_S[target]:.0f} s: {verdict} (exit {rc}, output {out})", flush=True)
    print(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 1 if rc_all else 0


if __name__ == "__main__":
    raise SystemExit(main())
