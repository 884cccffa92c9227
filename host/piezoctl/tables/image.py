"""Build and parse coefficient-table images (layout in ``common/interface.toml``).

An image is a little-endian header (:data:`interface.TABLE_HEADER`), a payload
of sections and a CRC-32 (zlib's) over everything before it. A section is an
8-byte header (id uint16, type uint16, count uint32) and ``count`` int16 or
int32 elements, zero-padded to a multiple of 4 bytes. See ``docs/tables.md``.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from .. import __version__, interface

__all__ = ["Section", "TableImage", "build_image", "parse_image", "check_image", "check_sections", "TableImageError",
           "tool_version_word"]

_FMT = {"uint16": "<H", "uint32": "<I", "int32": "<i"}
_SECTION_DTYPE = {interface.SECTION_TYPES["int16"]: np.dtype("<i2"),
                  interface.SECTION_TYPES["int32"]: np.dtype("<i4")}


class TableImageError(ValueError):
    """An image that the firmware would refuse; ``reason`` is a TABLE_REASONS name."""

    def __init__(self, reason: str, message: str):
        super().__init__(f"{reason}: {message}")
        self.reason = reason


@dataclass
class Section:
    """One payload section: an id and an int16 or int32 array."""

    id: int
    values: np.ndarray
    type: int = interface.SECTION_TYPES["int32"]


@dataclass
class TableImage:
    """A parsed image: header fields by name and sections by id."""

    header: dict
    sections: dict = field(default_factory=dict)
    crc: int = 0


def tool_version_word(version: str = __version__) -> int:
    """``major << 16 | minor << 8 | patch`` of a dotted version string."""
    major, minor, patch = (int(x) for x in (version.split(".") + ["0", "0"])[:3])
    return (major << 16) | (minor << 8) | patch


def _section_bytes(sec: Section) -> bytes:
    dt = _SECTION_DTYPE.get(sec.type)
    if dt is None:
        raise TableImageError("bad_section", f"section {sec.id}: unknown type {sec.type}")
    vals = np.asarray(sec.values)
    info = np.iinfo(dt)
    if vals.size and (vals.min() < info.min or vals.max() > info.max):
        raise TableImageError("out_of_range", f"section {sec.id}: values do not fit {dt}")
    data = vals.astype(dt).tobytes()
    data += b"\0" * ((-len(data)) % 4)
    return struct.pack("<HHI", sec.id, sec.type, vals.size) + data


def _milli(v: float) -> int:
    """V -> mV, um -> nm, rounded (the controller allows 1 LSB of difference)."""
    m = int(round(float(v) * 1000.0))
    if not -(1 << 31) <= m < (1 << 31):
        raise TableImageError("out_of_range", f"range end {v} does not fit the header")
    return m


def build_image(kind: str, sections: list[Section], *, table_version: int = 1,
                fit_nrmse: float = 0.0, build_time: int = 0, data_sha256: bytes = b"",
                axis: int = 0, drive_range_v: tuple[float, float] = (0.0, 0.0),
                position_range_um: tuple[float, float] = (0.0, 0.0),
                layout_version: int = interface.LAYOUT_VERSION,
                interface_crc: int = interface.INTERFACE_CRC32) -> bytes:
    """Assemble an image.

    Parameters
    ----------
    kind : str
        A key of ``interface.TABLE_KINDS``.
    sections : list of Section
        Payload sections, in order; ids must be unique.
    table_version : int
        User-visible version number.
    fit_nrmse : float
        Held-out NRMSE of the model (fraction, stored in ppm).
    build_time : int
        Unix time [s].
    data_sha256 : bytes
        SHA-256 of the recordings (the first 16 bytes are kept).
    axis : int
        Axis the table is built for (the controller's ``axis`` register).
    drive_range_v, position_range_um : (float, float)
        The stage the table is built for: drive [V] and position [um] of q15
        -1 and +1, as the controller reports them; stored in mV and nm. A
        controller that drives another stage refuses the table
        (``wrong_stage``); (0, 0) is no stage and is refused by any
        controller that knows its own.
    layout_version, interface_crc : int
        Override only to make deliberately wrong images for tests.

    Returns
    -------
    bytes
    """
    if kind not in interface.TABLE_KINDS:
        raise TableImageError("bad_kind", f"unknown table kind {kind!r}")
    ids = [s.id for s in sections]
    if len(set(ids)) != len(ids):
        raise TableImageError("bad_section", "duplicate section id")
    payload = b"".join(_section_bytes(s) for s in sections)
    values = {
        "magic": interface.TABLE_MAGIC, "layout_version": layout_version,
        "kind": interface.TABLE_KINDS[kind], "interface_crc": interface_crc,
        "header_bytes": interface.TABLE_HEADER_BYTES, "n_sections": len(sections),
        "payload_len": len(payload), "table_version": table_version,
        "q_signal_frac": interface.QFORMATS["q15"]["frac"],
        "q_coef_frac": interface.QFORMATS["q24"]["frac"],
        "fit_nrmse_ppm": int(round(min(max(fit_nrmse, 0.0), 4000.0) * 1e6)),
        "tool_version": tool_version_word(), "build_time": build_time,
        "data_sha256": (bytes(data_sha256) + b"\0" * 16)[:16],
        "axis": int(axis), "reserved": 0,
        "drive_min_mv": _milli(drive_range_v[0]), "drive_max_mv": _milli(drive_range_v[1]),
        "position_min_nm": _milli(position_range_um[0]), "position_max_nm": _milli(position_range_um[1]),
    }
    head = bytearray(interface.TABLE_HEADER_BYTES)
    for name, typ, off, count in interface.TABLE_HEADER:
        if typ == "bytes":
            head[off:off + count] = values[name]
        else:
            struct.pack_into(_FMT[typ], head, off, values[name])
    body = bytes(head) + payload
    total = len(body) + 4
    if total > interface.TABLE_MAX_BYTES:
        raise TableImageError("bad_length", f"image of {total} bytes exceeds {interface.TABLE_MAX_BYTES}")
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def parse_image(img: bytes) -> TableImage:
    """Check an image as the firmware does and return its fields.

    Raises
    ------
    TableImageError
        With the firmware's reason name, in the firmware's order of checks.
    """
    hb = interface.TABLE_HEADER_BYTES
    if len(img) < hb + 4 or len(img) > interface.TABLE_MAX_BYTES:
        raise TableImageError("bad_length", f"{len(img)} bytes")
    hdr = {}
    for name, typ, off, count in interface.TABLE_HEADER:
        hdr[name] = bytes(img[off:off + count]) if typ == "bytes" else struct.unpack_from(_FMT[typ], img, off)[0]
    if hdr["magic"] != interface.TABLE_MAGIC:
        raise TableImageError("bad_magic", f"magic {hdr['magic']:#010x}")
    if hdr["header_bytes"] != hb or hdr["payload_len"] != len(img) - hb - 4:
        raise TableImageError("bad_length", "header or payload length disagrees with the image size")
    crc = struct.unpack_from("<I", img, len(img) - 4)[0]
    if zlib.crc32(bytes(img[:-4])) & 0xFFFFFFFF != crc:
        raise TableImageError("bad_crc", "CRC-32 mismatch")
    if hdr["layout_version"] != interface.LAYOUT_VERSION:
        raise TableImageError("bad_layout_version", f"layout {hdr['layout_version']}, "
                              f"this tool speaks {interface.LAYOUT_VERSION}")
    if hdr["interface_crc"] != interface.INTERFACE_CRC32:
        raise TableImageError("bad_interface_crc", f"interface CRC {hdr['interface_crc']:#010x}")
    if hdr["q_signal_frac"] != 15 or hdr["q_coef_frac"] != 24 or hdr["reserved"] != 0:
        raise TableImageError("bad_layout_version", "Q formats differ, or the reserved field is not 0")
    sections, off, end = {}, hb, len(img) - 4
    for _ in range(hdr["n_sections"]):
        if end - off < 8:
            raise TableImageError("bad_length", "section header past the payload")
        sid, typ, count = struct.unpack_from("<HHI", img, off)
        off += 8
        dt = _SECTION_DTYPE.get(typ)
        if dt is None:
            raise TableImageError("bad_section", f"section {sid}: type {typ}")
        nbytes = count * dt.itemsize
        padded = nbytes + (-nbytes) % 4
        if padded > end - off:
            raise TableImageError("bad_length", f"section {sid} past the payload")
        if any(img[off + nbytes:off + padded]):
            raise TableImageError("bad_section", f"section {sid}: padding not zero")
        if sid in sections:
            raise TableImageError("bad_section", f"duplicate section {sid}")
        sections[sid] = np.frombuffer(bytes(img[off:off + nbytes]), dtype=dt).astype(np.int64)
        off += padded
    if off != end:
        raise TableImageError("bad_length", "bytes after the last section")
    return TableImage(header=hdr, sections=sections, crc=crc)


def check_image(img: bytes) -> TableImage:
    """:func:`parse_image` and :func:`check_sections`: what a commit checks
    before it runs the table's kernel (``piezo_table_check`` and
    ``piezo_table_check_specs``)."""
    t = parse_image(img)
    check_sections(t.header["kind"], t.sections)
    return t


def check_sections(kind: int, sections: dict) -> None:
    """The firmware's section checks (``table_image.c``, ``check_specs``):
    every section known for the kind, of its type and field count, every
    element in its range (``interface.TABLE_SECTION_RANGES``), and every
    section the kind needs present."""
    names = {v[0]: k for k, v in interface.TABLE_SECTIONS.items()}
    kind_name = {v: k for k, v in interface.TABLE_KINDS.items()}.get(kind)
    if kind_name is None or not any(kind_name in v[2] for v in interface.TABLE_SECTIONS.values()):
        raise TableImageError("bad_kind", f"kind {kind}")
    for sid, vals in sections.items():
        name = names.get(sid)
        if name is None or kind_name not in interface.TABLE_SECTIONS[name][2]:
            raise TableImageError("unknown_section", f"section {sid} is not part of a {kind_name} table")
        ranges = interface.TABLE_SECTION_RANGES[name]
        if ranges[0][0] is not None and len(vals) != len(ranges):
            raise TableImageError("bad_length", f"{name}: {len(vals)} elements, needs {len(ranges)}")
        for i, v in enumerate(vals):
            field, lo, hi = ranges[i] if ranges[0][0] is not None else ranges[0]
            if not lo <= int(v) <= hi:
                raise TableImageError("out_of_range", f"{name}[{i}]{' (' + field + ')' if field else ''} = {int(v)} "
                                      f"outside [{lo}, {hi}]")
    for name, (sid, _t, kinds) in interface.TABLE_SECTIONS.items():
        if kind_name in kinds and sid not in sections:
            raise TableImageError("missing_section", f"a {kind_name} table needs section {name}")
