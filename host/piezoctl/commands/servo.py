"""``piezoctl servo on|off --port PORT``: the closed loop on or off.

``on``: closed loop (mode ``feedback``, PID and notch) at the present
position: the setpoint becomes the position the sensor reads, and the
integrator starts from the drive applied now, so the drive does not jump. A
disarmed controller is armed (it must have no faults). Refused when the PID
gains are all zero (no loop to close: set them with ``piezoctl params set``
or ``piezoctl calibrate``).

``off``: open loop holding the present drive: the controller keeps applying
the drive of the moment (mode ``direct``, setpoint = that drive); the stage
then creeps and drifts as a piezo does without feedback. It does not disarm
(disarming ramps the drive to its safe value). On a disarmed controller the
servo is off already: nothing changes.

``off --disarm``: disarm as well (the drive ramps to its safe value at the
slew limit; the stage moves with it). Parameters change only disarmed.
"""

from __future__ import annotations

from ._options import add_output, add_port, emit


def add_parser(sub) -> None:
    p = sub.add_parser("servo", help="closed loop on (at the present position) or off (hold the drive)",
                       description=__doc__.splitlines()[0])
    p.add_argument("state", choices=["on", "off"], help="on: closed loop; off: open loop holding the drive")
    p.add_argument("--disarm", action="store_true",
                   help="with off: disarm too (the drive ramps to its safe value; needed to change parameters)")
    add_port(p)
    add_output(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..device import MODE_NAMES, connect
    from ..errors import CliError
    ctl = connect(args.port)
    st = ctl.status()
    on = args.state == "on"
    if args.disarm and on:
        raise CliError("--disarm goes with servo off")
    if args.disarm:
        if st["armed"]:
            ctl.arm(False)
            st = ctl.status()
        note = "disarmed: the drive ramps to its safe value"
    elif not on and not st["armed"]:
        note = "the controller is disarmed: the servo is off already (the drive rests at its safe value)"
    else:
        if on:
            p = ctl.read_params()
            if p["pid_kp_q24"] == 0 and p["pid_ki_q24"] == 0:
                raise CliError("the PID gains are 0: there is no loop to close (set pid_kp and pid_ki with "
                               "piezoctl params set, or run piezoctl calibrate); nothing changed")
        st = ctl.servo(on)
        note = ("closed loop at the present position" if on else "open loop holding the drive")
    res = {"port": args.port, "servo": args.state, "mode": MODE_NAMES.get(st["mode"], st["mode"]),
           "armed": bool(st["armed"]), "position_um": st["position_um"], "drive_v": st["drive_v"], "note": note}
    emit(args, res, f"servo {args.state}: {note}; mode {res['mode']}, position {st['position_um']:.4f} um, "
                    f"drive {st['drive_v']:.3f} V")
    return 0
