"""Table images for the firmware's parser tests: one valid, and one for each
way an image can be wrong behind a correct CRC (the parser must name each)."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from .. import interface
from ..tables.image import Section, build_image
from .export import CHeader


def _recrc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def valid_image() -> bytes:
    rng = np.random.default_rng(5)
    return build_image("kp_dcc", [
        Section(1, rng.integers(-32768, 32768, 11), interface.SECTION_TYPES["int16"]),
        Section(2, rng.integers(-(1 << 31), 1 << 31, 55)),
        Section(3, np.array([123456])),
    ], table_version=7, fit_nrmse=0.0123, build_time=1_800_000_000, data_sha256=bytes(range(32)))


def bad_images() -> dict[str, tuple[bytes, str]]:
    """name -> (image, expected reason name)."""
    good = valid_image()
    hb = interface.TABLE_HEADER_BYTES
    out = {
        "layout": (build_image("kp_dcc", [Section(1, np.arange(3))], layout_version=99), "bad_layout_version"),
        "interface": (build_image("kp_dcc", [Section(1, np.arange(3))], interface_crc=0x12345678),
                      "bad_interface_crc"),
    }
    body = bytearray(good[:-4])
    struct.pack_into("<H", body, hb + 2, 9)          # first section: unknown type
    out["section_type"] = (_recrc(bytes(body)), "bad_section")
    body = bytearray(good[:-4])
    struct.pack_into("<H", body, hb + 8 + 24, 1)     # second section gets the first's id
    out["duplicate_id"] = (_recrc(bytes(body)), "bad_section")
    body = bytearray(good[:-4])
    body[hb + 8 + 22] = 0xAA                         # padding after 11 int16
    out["padding"] = (_recrc(bytes(body)), "bad_section")
    body = bytearray(good[:-4])
    struct.pack_into("<I", body, hb + 4, 1 << 20)    # count far past the payload
    out["count"] = (_recrc(bytes(body)), "bad_length")
    body = bytearray(good[:-4])
    struct.pack_into("<I", body, 0, 0xDEADBEEF)
    out["magic"] = (_recrc(bytes(body)), "bad_magic")
    body = bytearray(good[:-4])
    struct.pack_into("<H", body, 14, 2)              # says 2 sections, has 3
    out["n_sections"] = (_recrc(bytes(body)), "bad_length")
    return out


def c_header() -> str:
    h = CHeader("tables")
    good = valid_image()
    h.define("GOLDEN_TABLE_LEN", len(good))
    h.array("golden_table", "uint8_t", good)
    h.define("GOLDEN_TABLE_CRC", struct.unpack_from("<I", good, len(good) - 4)[0])
    h.define("GOLDEN_TABLE_SECTION3_VALUE", 123456)
    bads = bad_images()
    names = list(bads)
    for i, name in enumerate(names):
        img, reason = bads[name]
        h.array(f"golden_bad_{i}", "uint8_t", img)
    h.parts.append("static const struct { const char *name; const uint8_t *img; uint32_t len; uint16_t reason; }"
                   " golden_bad[] = {\n" + "\n".join(
                       f'    {{"{n}", golden_bad_{i}, {len(bads[n][0])}u, {interface.TABLE_REASONS[bads[n][1]]}u}},'
                       for i, n in enumerate(names)) + "\n};")
    h.define("GOLDEN_BAD_N", len(names))
    return str(h)
