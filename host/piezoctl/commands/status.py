"""``piezoctl status --port PORT [--json]``: identity and status of a controller."""

from __future__ import annotations

import json

from ..device import connect


def add_parser(sub) -> None:
    p = sub.add_parser("status", help="identity and status of a controller")
    p.add_argument("--port", required=True, help="tcp:HOST:PORT, rtu:DEVICE[:BAUD] or usb[:VID:PID]")
    p.add_argument("--json", action="store_true", help="one JSON object (includes active_table_crc)")
    p.set_defaults(func=run)


def run(args) -> int:
    ctl = connect(args.port)
    st = ctl.status()
    idn = ctl.identity
    st.update({"fw_version": idn.fw_version, "layout_version": idn.layout_version,
               "interface_crc": idn.interface_crc, "n_axes": idn.n_axes, "axis": idn.axis,
               "tick_hz": idn.tick_hz, "scale": ctl.scale.to_dict()})
    if args.json:
        print(json.dumps(st, sort_keys=True))
        return 0
    print(f"controller on {args.port}: axis {idn.axis + 1} of {idn.n_axes}, {idn.tick_hz} Hz, "
          f"firmware {idn.fw_version >> 16}.{(idn.fw_version >> 8) & 255}.{idn.fw_version & 255}")
    print(f"  armed {bool(st['armed'])}, mode {st['mode']}, faults {', '.join(st['faults_names']) or 'none'}")
    print(f"  ticks {st['tick_count']}, overruns {st['overruns']}, clamps {st['clamps']}, "
          f"tick {st['tick_time_ns']} ns (max {st['tick_time_max_ns']} ns)")
    print(f"  position {st['position_um']:.4f} um, drive {st['drive_v']:.3f} V")
    print(f"  active table crc {st['active_table_crc']:#010x} version {st['active_table_version']} "
          f"kind {st['active_table_kind']}, previous {st['previous_table_crc']:#010x}, "
          f"last table command: {st['table_result_name']}")
    return 0
