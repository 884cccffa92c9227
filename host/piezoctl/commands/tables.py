"""``piezoctl tables build --model MODEL.json --out TABLE.bin``: a coefficient table.

The table is in the controller's q15 units, so the tool needs the
controller's drive and position ranges: from ``--port`` (read from the
controller), ``--drive-range``/``--position-range``, or the model file's
``controller_scale`` (written by ``piezoctl calibrate``), in that order.
The image is checked as the firmware will check it before it is written.
"""

from __future__ import annotations

from ..errors import CliError
from ..io.modelfile import load_model
from ..tables.from_model import SUPPORTED_KINDS, Scale, table_from_model
from ..tables.image import TableImageError, check_image


def add_parser(sub) -> None:
    p = sub.add_parser("tables", help="build coefficient tables from identified models")
    tsub = p.add_subparsers(dest="tables_command", metavar="SUBCOMMAND", required=True)
    b = tsub.add_parser("build", help="quantize a model file into a table image (TABLE.bin)",
                        description=__doc__.splitlines()[0])
    b.add_argument("--model", required=True, metavar="MODEL.json")
    b.add_argument("--out", required=True, metavar="TABLE.bin")
    b.add_argument("--port", help="read the controller's ranges from it (tcp:HOST:PORT, rtu:DEV[:BAUD], usb[:VID:PID])")
    b.add_argument("--drive-range", nargs=2, type=float, metavar=("V_MIN", "V_MAX"),
                   help="drive of q15 -1 and +1 [V]")
    b.add_argument("--position-range", nargs=2, type=float, metavar=("UM_MIN", "UM_MAX"),
                   help="position of q15 -1 and +1 [um]")
    b.add_argument("--axis", type=int, default=None,
                   help="controller axis the table is for (default: the --port controller's, else 0)")
    b.add_argument("--table-version", type=int, help="version stamped in the header (default: Unix time)")
    b.set_defaults(func=run_build)


def scale_for(args, model) -> Scale:
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
    print(f"{args.out}: {SUPPORTED_KINDS[model.kind]} table, {len(img)} bytes, version {t.header['table_version']}, "
          f"crc {t.crc:#010x}")
    return 0
