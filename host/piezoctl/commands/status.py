"""``piezoctl status --port PORT [--json] [--quiet]``: identity and status of a controller.

Text: five lines (identity, state, timing, position, tables). ``--json``: one
object with every field of :meth:`piezoctl.device.Controller.status` plus
``fw_version``, ``layout_version``, ``interface_crc``, ``n_axes``, ``axis``,
``tick_hz`` and ``scale`` (the controller's drive and position ranges).
"""

from __future__ import annotations

from ._options import add_output, add_port, emit


def add_parser(sub) -> None:
    p = sub.add_parser("status", help="identity and status of a controller")
    add_port(p)
    add_output(p, json_help="print one JSON object (every status field, includes active_table_crc)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..device import connect  # here: the start-up imports no numpy/scipy
    ctl = connect(args.port)
    st = ctl.status()
    idn = ctl.identity
    st.update({"fw_version": idn.fw_version, "layout_version": idn.layout_version,
               "interface_crc": idn.interface_crc, "n_axes": idn.n_axes, "axis": idn.axis,
               "tick_hz": idn.tick_hz, "scale": ctl.scale.to_dict()})
    emit(args, st, [
        f"controller on {args.port}: axis {idn.axis + 1} of {idn.n_axes}, {idn.tick_hz} Hz, "
        f"firmware {idn.fw_version >> 16}.{(idn.fw_version >> 8) & 255}.{idn.fw_version & 255}",
        f"  armed {bool(st['armed'])}, mode {st['mode']}, faults {', '.join(st['faults_names']) or 'none'}",
        f"  ticks {st['tick_count']}, overruns {st['overruns']}, clamps {st['clamps']}, "
        f"tick {st['tick_time_ns']} ns (max {st['tick_time_max_ns']} ns)",
        f"  position {st['position_um']:.4f} um, drive {st['drive_v']:.3f} V",
        f"  active table crc {st['active_table_crc']:#010x} version {st['active_table_version']} "
        f"kind {st['active_table_kind']}, previous {st['previous_table_crc']:#010x}, "
        f"last table command: {st['table_result_name']}"])
    return 0
