"""``piezoctl flash --port PORT TABLE.bin``: upload, verify, commit, confirm.

The image is checked locally first; then it is written to the controller's
staged bank (progress on stderr), read back and compared byte for byte (and
by CRC), committed, and the tool waits until the controller reports it as
the active table. A refusal prints the controller's reason and exits 2; the
table that was running keeps running.
"""

from __future__ import annotations

import sys
import time
import zlib

from ..device import connect
from ..errors import CliError, ControllerRefused
from ..tables.image import TableImageError, parse_image


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
    p = sub.add_parser("flash", help="upload a table image, verify, commit", description=__doc__.splitlines()[0])
    p.add_argument("--port", required=True, help="tcp:HOST:PORT, rtu:DEVICE[:BAUD] or usb[:VID:PID]")
    p.add_argument("table", metavar="TABLE.bin")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def flash_image(ctl, img: bytes, *, quiet: bool = False, timeout_s: float = 2.0) -> int:
    """Upload, verify, commit and confirm ``img`` on ``ctl``; returns the active CRC.

    Raises
    ------
    CliError
        The image is refused locally or by the controller, or does not verify.
    """
    try:
        t = parse_image(img)
    except TableImageError as exc:
        raise CliError(f"not a valid table image: {exc}") from None
    ctl.upload_table(img, None if quiet else progress_bar("upload"))
    back = ctl.read_staged(len(img), None if quiet else progress_bar("verify"))
    if back != img:
        bad = next(i for i, (a, b) in enumerate(zip(back, img)) if a != b)
        raise CliError(f"read-back differs from the image at byte {bad}: not committed")
    if zlib.crc32(back[:-4]) & 0xFFFFFFFF != t.crc:
        raise CliError("read-back CRC mismatch: not committed")
    result = ctl.commit_table()
    if result != "ok":
        raise ControllerRefused(f"the controller refused the table: {result} (the previous table keeps running)")
    deadline = time.monotonic() + timeout_s
    while ctl.status()["active_table_crc"] != t.crc:
        if time.monotonic() > deadline:
            raise CliError("the controller accepted the table but does not report it active")
        time.sleep(0.01)
    return t.crc


def run(args) -> int:
    try:
        with open(args.table, "rb") as fh:
            img = fh.read()
    except OSError as exc:
        raise CliError(f"{args.table}: {exc.strerror}") from None
    ctl = connect(args.port)
    crc = flash_image(ctl, img, quiet=args.quiet)
    st = ctl.status()
    print(f"{args.table}: active on {args.port}, crc {crc:#010x}, version {st['active_table_version']}")
    return 0
