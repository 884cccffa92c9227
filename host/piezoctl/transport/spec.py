"""PORT strings: where the controller is.

========================  ================================================
``tcp:HOST:PORT``         Modbus TCP (``HOST`` may be ``[v6addr]``; PORT
                          defaults to 502 when omitted)
``rtu:DEVICE[:BAUD[:P]]`` Modbus RTU on a serial device, 19200 baud and
                          even parity by default (the serial line
                          specification's defaults); P is N, E or O
``usb[:VID:PID]``         USB vendor-class bulk endpoints (hex ids,
                          default :data:`piezoctl.transport.usb.DEFAULT_VID`
                          and ``DEFAULT_PID``)
========================  ================================================
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import PortSpecError

__all__ = ["PortSpec", "parse_port", "FORMS"]

FORMS = "tcp:HOST:PORT, rtu:DEVICE[:BAUD[:PARITY]] or usb[:VID:PID]"
DEFAULT_TCP_PORT = 502
DEFAULT_BAUD = 19200
DEFAULT_PARITY = "E"


@dataclass(frozen=True)
class PortSpec:
    """A parsed PORT string; ``kind`` is ``"tcp"``, ``"rtu"`` or ``"usb"``."""

    kind: str
    text: str
    host: str | None = None
    port: int | None = None
    device: str | None = None
    baud: int | None = None
    parity: str | None = None
    vid: int | None = None
    pid: int | None = None


def _bad(text: str, why: str) -> PortSpecError:
    return PortSpecError(f"port {text!r}: {why} (expected {FORMS})")


def _int(text: str, field: str, value: str, lo: int, hi: int, base: int = 10) -> int:
    try:
        n = int(value, base)
    except ValueError:
        raise _bad(text, f"{field} {value!r} is not a number") from None
    if not lo <= n <= hi:
        raise _bad(text, f"{field} {n} is outside {lo}..{hi}")
    return n


def parse_port(text: str) -> PortSpec:
    """Parses a PORT string; raises :class:`PortSpecError` naming what is wrong.

    >>> parse_port("tcp:127.0.0.1:5020").port
    5020
    >>> parse_port("rtu:/dev/ttyUSB0:115200").baud
    115200
    >>> hex(parse_port("usb:1209:0001").vid)
    '0x1209'
    """
    if not isinstance(text, str) or not text:
        raise _bad(str(text), "empty")
    kind, _, rest = text.partition(":")
    kind = kind.lower()
    if kind == "tcp":
        if not rest:
            raise _bad(text, "no host")
        if rest.startswith("["):
            host, sep, tail = rest[1:].partition("]")
            if not sep or not host:
                raise _bad(text, "unterminated [IPv6 address]")
            if tail and not tail.startswith(":"):
                raise _bad(text, f"unexpected {tail!r} after the address")
            has_port, port_text = tail.startswith(":"), tail[1:]
        else:
            host, sep, port_text = rest.partition(":")
            has_port = bool(sep)
            if not host:
                raise _bad(text, "no host")
            if ":" in port_text:
                raise _bad(text, "too many fields (put an IPv6 address in [])")
        port = _int(text, "TCP port", port_text, 1, 65535) if has_port else DEFAULT_TCP_PORT
        return PortSpec("tcp", text, host=host, port=port)
    if kind == "rtu":
        if not rest:
            raise _bad(text, "no serial device")
        fields = rest.split(":")
        device = fields[0]
        if not device:
            raise _bad(text, "no serial device")
        if len(fields) > 3:
            raise _bad(text, "too many fields")
        baud = _int(text, "baud rate", fields[1], 50, 4_000_000) if len(fields) > 1 else DEFAULT_BAUD
        parity = DEFAULT_PARITY
        if len(fields) > 2:
            parity = fields[2].upper()
            if parity not in ("N", "E", "O"):
                raise _bad(text, f"parity {fields[2]!r} is not N, E or O")
        return PortSpec("rtu", text, device=device, baud=baud, parity=parity)
    if kind == "usb":
        from .usb import DEFAULT_PID, DEFAULT_VID
        if rest == "":
            return PortSpec("usb", text, vid=DEFAULT_VID, pid=DEFAULT_PID)
        fields = rest.split(":")
        if len(fields) != 2:
            raise _bad(text, "USB ids must be VID:PID")
        vid = _int(text, "USB vendor id", fields[0], 0, 0xFFFF, 16)
        pid = _int(text, "USB product id", fields[1], 0, 0xFFFF, 16)
        return PortSpec("usb", text, vid=vid, pid=pid)
    raise _bad(text, f"unknown transport {kind!r}")
