"""``piezoctl calibrate --target sil|PORT --out DIR``: from unknown to compensated.

Seven steps, each announced on stderr when it starts and when it ends: connect, excitation (played and recorded
by the firmware), identification with held-out model choice and dynamics,
checks, table build and flash, acceptance test (triangles at 1, 10, 50 Hz and
a multitone, uncompensated and compensated; rollback if worse), report.
Writes DIR/model.json, DIR/table.bin, DIR/summary.json, DIR/report.html and
DIR/data/ (the recordings). ``docs/calibrate.md`` describes it. On a two-axis
controller (identity n_axes == 2; axis 2 at TCP port PORT + 1, or unit id 2)
axis 2 is calibrated the same way into DIR/axis2/, then the cross-axis
coupling both ways (``piezoctl.calibrate.coupling``): coupling tables flashed,
``coupling`` added to summary.json and report.html.

Output: one line naming the table and the report; ``--json`` prints a summary
object instead (:func:`result_of`); ``--quiet`` drops the progress.
"""

from __future__ import annotations

import contextlib
import pathlib

from ._options import Progress, add_output, emit


def add_parser(sub) -> None:
    p = sub.add_parser("calibrate", help="calibrate a stage end to end (identify, flash, accept, report)",
                       description=__doc__.splitlines()[0])
    p.add_argument("--target", required=True, help="sil (start a virtual controller), qemu (the firmware image "
                                                    "with the stage model under QEMU, over Modbus RTU) or a PORT: "
                                                    "tcp:HOST:PORT, rtu:DEVICE[:BAUD], usb[:VID:PID]")
    p.add_argument("--image", metavar="ELF", help="with --target qemu: the PIL image (default: build piezoctl-pil)")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--stage", metavar="PARAMS.json", help="with --target sil: the stage parameter file")
    p.add_argument("--models", default="eupi,kp", help="candidate model kinds, best held-out error wins "
                                                       "(default eupi,kp)")
    add_output(p, json_help="print a summary (model, table, tracking, resonance, report path) as one JSON "
                            "object on stdout")
    p.set_defaults(func=run)


def _target_of(port: str) -> dict:
    return {"kind": "port", "transport": port.split(":", 1)[0], "port": port}


def _calibrate(port: str, out: pathlib.Path, kinds, target: dict | None = None, timeout: float = 1.0,
               args=None) -> dict:
    """Axis 1; on a two-axis controller also axis 2 (DIR/axis2) and the cross-axis coupling."""
    from ..calibrate.pipeline import calibrate
    from ..device import connect
    ctl = connect(port, timeout=timeout)
    summary = calibrate(ctl, out, kinds=kinds, target=target or _target_of(port), args=args)
    if ctl.identity.n_axes == 2:
        from ..calibrate.coupling import calibrate_two_axis
        summary = calibrate_two_axis(ctl, port, out, summary, kinds=kinds, args=args)
    return summary


def result_of(summary: dict, out: pathlib.Path) -> dict:
    """The ``--json`` object: what was flashed, how well it tracks, where the files are."""
    return {"model": summary["model"], "table_kind": summary["table_kind"], "table_crc_hex": summary["table_crc_hex"],
            "heldout_nrmse": summary["heldout_nrmse"], "rolled_back": summary["rolled_back"],
            "tracking": summary["tracking"], "resonance_hz": summary["dynamics"]["resonance_hz"],
            "duration_s": summary["duration_s"], "target": summary["target"],
            "report": str(out / "report.html"), "summary": str(out / "summary.json")}


def run(args) -> int:
    from ..calibrate.target import QemuTarget, SilTarget
    out = pathlib.Path(args.out)
    kinds = tuple(k.strip() for k in args.models.split(",") if k.strip())
    if args.target == "sil":
        with contextlib.ExitStack() as stack:
            with Progress(args, "start the virtual controller (sil_stage)"):
                sil = stack.enter_context(SilTarget(stage=args.stage))
            summary = _calibrate(sil.port, out, kinds, {"kind": "sil", "transport": "tcp"}, args=args)
    elif args.target == "qemu":
        # the recorder's readout walks the buffer per register (regmap.c): the
        # last windows take longer than a second of emulated work
        with contextlib.ExitStack() as stack:
            with Progress(args, "start the firmware image under QEMU"):
                pil = stack.enter_context(QemuTarget(image=args.image))
            summary = _calibrate(pil.port, out, kinds, pil.describe(), timeout=10.0, args=args)
    else:
        summary = _calibrate(args.target, out, kinds, args=args)
    emit(args, result_of(summary, out),
         f"calibrated: {summary['model']} -> {summary['table_kind']} table {summary['table_crc_hex']}; "
         f"report {out / 'report.html'}")
    return 0
