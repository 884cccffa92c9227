"""Seed inputs of tests/fuzz/fuzz_commit.c: the reference tables (built for
the default SIL stage) without their CRC, after a short reference path; and
the same with one section element pushed to a range end.

    python3 tests/fuzz/seed_commit.py DIR     (needs the host package: PYTHONPATH=host)
"""

import os
import struct
import sys

from piezoctl.fixtures.ctl import dcc_image, eupi_image


def seed(img: bytes, refs=(0, 16000, -16000, 8000, 0)) -> bytes:
    return bytes([len(refs)]) + struct.pack(f"<{len(refs)}h", *refs) + img[:-4]


def main(out: str) -> int:
    os.makedirs(out, exist_ok=True)
    imgs = {"dcc": dcc_image()[0], "eupi": eupi_image()[0]}
    for name, img in imgs.items():
        with open(os.path.join(out, f"{name}"), "wb") as fh:
            fh.write(seed(img))
        with open(os.path.join(out, f"{name}_noref"), "wb") as fh:
            fh.write(seed(img, ()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
