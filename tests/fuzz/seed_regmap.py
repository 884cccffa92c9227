"""Seed inputs of tests/fuzz/fuzz_regmap.c (its operation encoding): valid
requests as the host sends them -- unlock, the reference tables uploaded in
chunks, commit, ticks, read-back, rollback -- and a few refused ones.

    python3 tests/fuzz/seed_regmap.py DIR     (needs the host package: PYTHONPATH=host)
"""

import os
import struct
import sys

from piezoctl.fixtures.ctl import dcc_image, eupi_image

WINDOW = 121
RAW, TICKS, UNLOCK, CHUNK, SEAL, COMMIT, ROLLBACK, CLEAR, READBACK = range(9)


def unlock(key=None):
    return bytes([UNLOCK, 0]) if key is None else bytes([UNLOCK, 1]) + struct.pack("<H", key)


def upload(img: bytes) -> bytes:
    out = bytearray()
    for off in range(0, len(img), 2 * WINDOW):
        part = img[off:off + 2 * WINDOW]
        if len(part) % 2:
            part += b"\0"
        out += bytes([CHUNK]) + struct.pack("<H", off // 2) + bytes([len(part) // 2 - 1]) + part
    return bytes(out)


def ticks(n=10, adc=0):
    return bytes([TICKS, n - 1]) + struct.pack("<h", adc)


def raw(pdu: bytes) -> bytes:
    return bytes([RAW, len(pdu)]) + pdu


def main(root: str) -> None:
    os.makedirs(root, exist_ok=True)
    dcc, _ = dcc_image()
    eupi, _ = eupi_image()
    bad = bytearray(dcc)
    bad[60] ^= 0x40  # a coefficient changed, CRC resealed: the commit's checks decide
    seeds = {
        "upload_commit": unlock() + upload(dcc) + bytes([READBACK, 0, READBACK, 1]) + bytes([COMMIT])
        + ticks(),
        "two_tables_rollback": unlock() + upload(dcc) + bytes([COMMIT]) + ticks() + unlock()
        + upload(eupi) + bytes([COMMIT]) + ticks() + bytes([ROLLBACK]) + ticks(),
        "resealed": unlock() + upload(bytes(bad)) + bytes([SEAL, COMMIT]) + ticks(),
        "locked": unlock(0x1234) + upload(dcc) + bytes([COMMIT, CLEAR]),
        "raw_requests": raw(bytes([3, 0x10, 0, 0, 7])) + raw(bytes([4, 1, 0, 0, 40]))
        + raw(bytes([6, 0x10, 0, 0x50, 0xA5])) + raw(bytes([16, 0x20, 0x80, 0, 1, 2, 0, 3]))
        + raw(bytes([23, 0x20, 2, 0, 4, 0x20, 0, 0, 2, 4, 0, 0, 0, 8])),
        # the recorder window far past any recording (rec_read_index 0xFFFFFF00): once a
        # loop of ~2^32 steps per register in rec_sample, now answered at once
        "rec_index_far": raw(bytes([16, 0x17, 0x00, 0, 2, 4, 0xFF, 0xFF, 0xFF, 0x00]))
        + raw(bytes([3, 0x17, 0x02, 0, 125]))
        + raw(bytes([23, 0x17, 0x02, 0, 125, 0x17, 0x00, 0, 2, 4, 0xFF, 0xFF, 0xFF, 0xF0])),
    }
    for name, data in seeds.items():
        with open(os.path.join(root, name), "wb") as fh:
            fh.write(data)


if __name__ == "__main__":
    main(sys.argv[1])
