"""``piezoctl position --port PORT [--follow]``: where the stage is.

One reading of the position [um], the reference [um], the error [um], the
drive [V], the mode and whether the controller is armed. ``--follow`` prints
a reading every ``--interval`` seconds until Ctrl-C (or ``--count`` readings);
with ``--json`` each reading is one JSON object on its own line.
"""

from __future__ import annotations

import sys
import time

from ..errors import CliError
from ._options import add_output, add_port, emit


def add_parser(sub) -> None:
    p = sub.add_parser("position", help="the stage's position (once, or --follow until Ctrl-C)",
                       description=__doc__.splitlines()[0])
    add_port(p)
    p.add_argument("--follow", action="store_true", help="keep printing readings until Ctrl-C")
    p.add_argument("--interval", type=float, default=0.1, metavar="S",
                   help="seconds between readings with --follow (default 0.1)")
    p.add_argument("--count", type=int, default=None, metavar="N",
                   help="with --follow: stop after N readings")
    add_output(p)
    p.set_defaults(func=run)


def reading(ctl) -> dict:
    """One reading of a controller: position, reference and error [um], drive [V], mode, armed."""
    from ..device import MODE_NAMES
    st = ctl.status()
    sc = ctl.scale
    return {"t": time.time(), "position_um": st["position_um"],
            "reference_um": float(sc.position_from_fs(st["reference_q15"] / 32768.0)),
            "error_um": st["error_q15"] / 32768.0 * sc.p_half, "drive_v": st["drive_v"],
            "mode": MODE_NAMES.get(st["mode"], str(st["mode"])), "armed": bool(st["armed"]),
            "faults": st["faults_names"]}


def _line(r: dict) -> str:
    return (f"position {r['position_um']:10.4f} um  reference {r['reference_um']:10.4f} um  "
            f"error {r['error_um']:+8.4f} um  drive {r['drive_v']:8.3f} V  mode {r['mode']}"
            f"{'' if r['armed'] else ' (disarmed)'}" + (f"  faults {', '.join(r['faults'])}" if r["faults"] else ""))


def run(args) -> int:
    from ..device import connect
    if args.interval <= 0 or (args.count is not None and args.count < 1):
        raise CliError("--interval must be > 0 and --count >= 1")
    ctl = connect(args.port)
    if not args.follow:
        r = reading(ctl)
        emit(args, {"port": args.port, **r}, _line(r))
        return 0
    n = 0
    try:
        next_t = time.monotonic()
        while args.count is None or n < args.count:
            r = reading(ctl)
            emit(args, {"port": args.port, **r}, _line(r))
            sys.stdout.flush()  # a reader at the other end of a pipe sees each reading now
            n += 1
            next_t += args.interval
            time.sleep(max(0.0, next_t - time.monotonic()))
    except KeyboardInterrupt:
        pass  # Ctrl-C is how --follow ends
    return 0
