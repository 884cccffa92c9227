"""``piezoctl tables build|list|rollback``: coefficient tables.

``tables build --model MODEL.json --out TABLE.bin`` quantizes a model into a
table image. ``tables list --port PORT`` shows the tables a controller holds
(active, previous, staged, coupling: kind, CRC, version, stage identity);
``tables rollback --port PORT`` returns to the previous table and shows the
controller's reason when it refuses.


The table is in the controller's q15 units, so the tool needs the
controller's drive and position ranges: from ``--port`` (read from the
controller), ``--drive-range``/``--position-range``, or the model file's
``controller_scale`` (written by ``piezoctl calibrate``), in that order.
The image is checked as the firmware will check it before it is written.
"""

from __future__ import annotations

from ..errors import CliError
from ._options import add_output, add_port, emit


def add_parser(sub) -> None:
    p = sub.add_parser("tables", help="coefficient tables: build from a model, list a controller's, roll back")
    tsub = p.add_subparsers(dest="tables_command", metavar="SUBCOMMAND", required=True)
    b = tsub.add_parser("build", help="quantize a model file into a table image (TABLE.bin)",
                        description=__doc__.splitlines()[0])
    b.add_argument("--model", required=True, metavar="MODEL.json")
    b.add_argument("--out", required=True, metavar="TABLE.bin")
    add_port(b, required=False, help="read the controller's ranges (and axis) from it")
    b.add_argument("--drive-range", nargs=2, type=float, metavar=("V_MIN", "V_MAX"),
                   help="drive of q15 -1 and +1 [V]")
    b.add_argument("--position-range", nargs=2, type=float, metavar=("UM_MIN", "UM_MAX"),
                   help="position of q15 -1 and +1 [um]")
    b.add_argument("--axis", type=int, default=None,
                   help="controller axis the table is for (default: the --port controller's, else 0)")
    b.add_argument("--table-version", type=int, help="version stamped in the header (default: Unix time)")
    add_output(b)
    b.set_defaults(func=run_build)
    ls = tsub.add_parser("list", help="the tables a controller holds: active, previous, staged, coupling",
                         description="The tables a controller holds: kind, CRC, version and stage identity "
                                     "of the active table, the previous one (the rollback target), an upload "
                                     "staged but not committed, and the cross-coupling table.")
    add_port(ls)
    add_output(ls)
    ls.set_defaults(func=run_list)
    rb = tsub.add_parser("rollback", help="back to the previous table (the controller's reason if it refuses)",
                         description="Make the previous table active again (flash and RAM); the controller "
                                     "refuses with its reason (no_previous, busy, storage_failed, ...) and "
                                     "the running table keeps running.")
    add_port(rb)
    add_output(rb)
    rb.set_defaults(func=run_rollback)


ROLES = ("active", "previous", "staged", "coupling")


def _table_line(role: str, t: dict | None) -> str:
    if t is None:
        return f"  {role:9s} none"
    if t.get("kind") is None:
        return f"  {role:9s} {t['bytes']} bytes uploaded (no complete header)"
    sg = t["stage"]
    ver = "-" if t["version"] is None else str(t["version"])
    extra = f", {t['bytes']} bytes, not committed" if role == "staged" else ""
    return (f"  {role:9s} {t['kind']:14s} crc {t['crc']:#010x} version {ver:>10s}  stage: axis {sg['axis']}, "
            f"drive {sg['drive_min_v']:g}..{sg['drive_max_v']:g} V, position {sg['position_min_um']:g}.."
            f"{sg['position_max_um']:g} um{extra}")


def run_list(args) -> int:
    from ..device import connect
    ctl = connect(args.port)
    tabs = ctl.tables()
    emit(args, {"port": args.port, **tabs},
         [f"tables on {args.port}:"] + [_table_line(r, tabs[r]) for r in ROLES])
    return 0


def run_rollback(args) -> int:
    from ..device import TABLE_REASON_HELP, connect
    from ..errors import ControllerRefused
    ctl = connect(args.port)
    before = ctl.tables()
    reason = ctl.rollback_table()
    if reason != "ok":
        raise ControllerRefused(f"the controller refused the rollback: {reason} "
                                f"({TABLE_REASON_HELP.get(reason, 'see docs/protocol.md')}); "
                                "the running table keeps running")
    after = ctl.tables()
    emit(args, {"port": args.port, "result": reason, "before": before, "after": after},
         [f"rolled back on {args.port}: the running table is now"] + [_table_line("active", after["active"])])
    return 0


def scale_for(args, model):
    """The controller's ranges (a :class:`piezoctl.tables.from_model.Scale`) for a table build."""
    from ..tables.from_model import Scale
    if args.port:
        from ..device import connect
        ctl = connect(args.port)
        if args.axis is None:
            args.axis = ctl.identity.axis
        return ctl.scale
    if args.drive_range and args.position_range:
        return Scale(*args.drive_range, *args.position_range)
    if args.drive_range or args.position_range:
        raise CliError("give both --drive-range and --position-range")
    cs = model.params.get("controller_scale")
    if isinstance(cs, dict):
        try:
            return Scale(float(cs["drive_min_v"]), float(cs["drive_max_v"]),
                         float(cs["position_min_um"]), float(cs["position_max_um"]))
        except (KeyError, TypeError, ValueError):
            raise CliError(f"{args.model}: controller_scale is malformed") from None
    raise CliError("the controller's ranges are needed: give --port, or --drive-range and --position-range")


def run_build(args) -> int:
    # heavy imports here, not at the top: piezoctl --help stays fast
    from ..io.modelfile import load_model
    from ..tables.from_model import SUPPORTED_KINDS, table_from_model
    from ..tables.image import TableImageError, check_image
    model = load_model(args.model)
    if model.kind not in SUPPORTED_KINDS:
        raise CliError(f"{args.model}: model kind {model.kind!r} has no firmware table "
                       f"(supported: {', '.join(SUPPORTED_KINDS)})")
    scale = scale_for(args, model)
    try:
        img = table_from_model(model, scale, table_version=args.table_version, axis=args.axis or 0)
        t = check_image(img)
    except TableImageError as exc:
        raise CliError(f"table refused: {exc}") from None
    with open(args.out, "wb") as fh:
        fh.write(img)
    emit(args, {"out": args.out, "kind": SUPPORTED_KINDS[model.kind], "bytes": len(img),
                "version": t.header["table_version"], "crc": t.crc, "axis": t.header["axis"]},
         f"{args.out}: {SUPPORTED_KINDS[model.kind]} table, {len(img)} bytes, version {t.header['table_version']}, "
         f"crc {t.crc:#010x}")
    return 0
