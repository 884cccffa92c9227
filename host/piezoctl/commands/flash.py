"""``piezoctl flash --port PORT TABLE.bin``: upload, verify, commit, confirm.

The image is checked locally first; then :meth:`piezoctl.device.Controller.flash`
writes it to the controller's staged bank (progress on stderr), reads it back
and compares it byte for byte (and by CRC), commits it, and waits until the
controller reports it running. A refusal prints the controller's reason and
exits 4; the table that was running keeps running.
"""

from __future__ import annotations

import sys

from ..errors import CliError
from ._options import add_output, add_port, emit


def progress_bar(label: str):
    """A text progress bar on stderr: call with (done, total)."""
    def show(done: int, total: int) -> None:
        n = 30 * done // max(total, 1)
        sys.stderr.write(f"\r{label:8s} [{'#' * n}{'.' * (30 - n)}] {done}/{total} bytes")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show


def add_parser(sub) -> None:
    p = sub.add_parser("flash", help="upload a table image, verify, commit, confirm",
                       description=__doc__.splitlines()[0])
    add_port(p)
    p.add_argument("table", metavar="TABLE.bin")
    add_output(p)
    p.set_defaults(func=run)


def flash_image(ctl, img: bytes, *, quiet: bool = False, timeout_s: float = 2.0) -> int:
    """:meth:`Controller.flash` with progress bars on stderr unless ``quiet``;
    returns the running table's CRC (kept for calibrate's pipeline)."""
    return ctl.flash(img, progress=None if quiet else _bars(), timeout_s=timeout_s)["crc"]


def _bars():
    """A progress(step, done, total) callback: one bar per step."""
    bars = {}

    def show(step: str, done: int, total: int) -> None:
        bars.setdefault(step, progress_bar(step))(done, total)
    return show


def run(args) -> int:
    from ..device import connect
    try:
        with open(args.table, "rb") as fh:
            img = fh.read()
    except OSError as exc:
        raise CliError(f"{args.table}: {exc.strerror}") from None
    ctl = connect(args.port)
    res = ctl.flash(img, progress=None if (args.quiet or args.json) else _bars())
    res.update({"table": args.table, "port": args.port})
    emit(args, res, f"{args.table}: running on {args.port}: {res['kind']} table, crc {res['crc']:#010x}, "
                    f"version {res['version']}, {res['bytes']} bytes")
    return 0
