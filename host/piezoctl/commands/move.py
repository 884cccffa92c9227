"""``piezoctl move --port PORT --position UM [--wait]``: move the stage.

Sets the controller's setpoint to the position UM [um] (reference source:
the setpoint; a running wave is left behind). The controller must be armed in
a mode that takes a position as its reference: ``feedback`` or
``ff_feedback`` (closed loop: ``piezoctl servo on``), or ``open_loop`` /
``feedforward`` (through the table, no sensor correction). Servo off (mode
``direct``) holds a drive, not a position: ``move`` is refused there.

``--wait`` polls until the position stays within ``--tolerance`` of UM for
``--settle`` seconds, or ``--timeout`` passes; it reports the final position
and error, and exits 1 when the stage did not settle in time.
"""

from __future__ import annotations

import time

from ..errors import CheckFailed, CliError
from ._options import add_output, add_port, emit

POSITION_MODES = ("open_loop", "feedforward", "ff_feedback", "feedback")


def add_parser(sub) -> None:
    p = sub.add_parser("move", help="move the stage to a position [um] (--wait: until settled)",
                       description=__doc__.splitlines()[0])
    add_port(p)
    p.add_argument("--position", type=float, required=True, metavar="UM", help="target position [um]")
    p.add_argument("--wait", action="store_true", help="wait until settled within --tolerance, or --timeout")
    p.add_argument("--tolerance", type=float, default=0.05, metavar="UM",
                   help="settled when |position - target| <= this [um] (default 0.05)")
    p.add_argument("--settle", type=float, default=0.05, metavar="S",
                   help="... for this long [s] (default 0.05)")
    p.add_argument("--timeout", type=float, default=2.0, metavar="S", help="give up after this long [s] (default 2)")
    add_output(p)
    p.set_defaults(func=run)


def settle(ctl, target_um: float, tolerance_um: float, settle_s: float, timeout_s: float) -> dict:
    """Poll until the position stays within ``tolerance_um`` of ``target_um``
    for ``settle_s`` seconds, or ``timeout_s`` passes.

    Returns
    -------
    dict
        ``settled`` (bool), ``time_s`` (from the call to the first reading of
        the settled stretch, or the timeout), ``position_um`` and
        ``error_um`` (position - target) of the last reading.
    """
    t0 = time.monotonic()
    inside_since = None
    while True:
        now = time.monotonic()
        y = ctl.status()["position_um"]
        if abs(y - target_um) <= tolerance_um:
            inside_since = now if inside_since is None else inside_since
            if now - inside_since >= settle_s:
                return {"settled": True, "time_s": inside_since - t0, "position_um": y, "error_um": y - target_um}
        else:
            inside_since = None
        if now - t0 > timeout_s:
            return {"settled": False, "time_s": now - t0, "position_um": y, "error_um": y - target_um}
        time.sleep(0.005)


def run(args) -> int:
    from ..device import MODE_NAMES, connect
    if not (args.tolerance > 0 and args.settle >= 0 and args.timeout > 0):
        raise CliError("--tolerance and --timeout must be > 0, --settle >= 0")
    ctl = connect(args.port)
    sc = ctl.scale
    # the positions a q15 setpoint can name: -32768 .. 32767 LSB
    lo, hi = sorted((float(sc.position_from_fs(-1.0)), float(sc.position_from_fs(32767 / 32768.0))))
    if not lo <= args.position <= hi:
        raise CliError(f"position {args.position:g} um is outside the stage's range [{lo:g}, {hi:g}] um; "
                       "nothing changed")
    st = ctl.status()
    mode = MODE_NAMES.get(st["mode"], str(st["mode"]))
    if not st["armed"] or mode not in POSITION_MODES:
        why = ("the controller is disarmed" if not st["armed"] else
               "the servo is off (mode direct: it holds a drive, not a position)" if mode == "direct" else
               f"mode {mode} takes no position")
        raise CliError(f"cannot move: {why}; run piezoctl servo on first; nothing changed")
    if st["faults"]:
        raise CliError(f"cannot move: faults {', '.join(st['faults_names'])}; nothing changed")
    ctl.set_setpoint_um(args.position)
    res = {"port": args.port, "target_um": args.position, "mode": mode, "waited": bool(args.wait)}
    if not args.wait:
        y = ctl.status()["position_um"]
        res.update({"position_um": y, "error_um": y - args.position})
        emit(args, res, f"setpoint {args.position:g} um (mode {mode}); position now {y:.4f} um")
        return 0
    res.update(settle(ctl, args.position, args.tolerance, args.settle, args.timeout))
    res["tolerance_um"] = args.tolerance
    line = (f"{'settled' if res['settled'] else 'NOT settled'} at {res['position_um']:.4f} um, error "
            f"{res['error_um']:+.4f} um (tolerance {args.tolerance:g} um) after {res['time_s']:.3f} s, mode {mode}")
    emit(args, res, line)
    if not res["settled"]:
        raise CheckFailed(f"the stage did not settle within {args.tolerance:g} um of {args.position:g} um in "
                          f"{args.timeout:g} s (error {res['error_um']:+.4f} um)")
    return 0
