"""Modbus PDUs, encoded and decoded here for the USB bulk transport (TCP and
RTU go through pymodbus). Modbus Application Protocol V1.1b3: FC 3/4 (6.3,
6.4), FC 16 (6.12), exception responses (7). Big-endian fields."""

from __future__ import annotations

import struct

from .errors import ModbusExceptionError, ProtocolError, exception_text

__all__ = ["read_request", "write_request", "parse_read_response", "parse_write_response"]


def read_request(function: int, address: int, count: int) -> bytes:
    """FC 3 or 4: function, start, quantity."""
    return struct.pack(">BHH", function, address, count)


def write_request(address: int, values: list[int]) -> bytes:
    """FC 16: function, start, quantity, byte count, values."""
    n = len(values)
    return struct.pack(f">BHHB{n}H", 16, address, n, 2 * n, *values)


def _check_exception(pdu: bytes, function: int, what: str) -> None:
    if not pdu:
        raise ProtocolError(f"{what}: empty answer")
    if pdu[0] == function | 0x80:
        if len(pdu) != 2:
            raise ProtocolError(f"{what}: exception response of {len(pdu)} bytes")
        raise ModbusExceptionError(f"{what}: {exception_text(pdu[1])}", pdu[1], function)
    if pdu[0] != function:
        raise ProtocolError(f"{what}: answer has function {pdu[0]:#04x}, asked {function:#04x}")


def parse_read_response(pdu: bytes, function: int, count: int, what: str) -> list[int]:
    """Registers of an FC 3/4 response; raises on an exception or a wrong shape."""
    _check_exception(pdu, function, what)
    if len(pdu) != 2 + 2 * count or pdu[1] != 2 * count:
        raise ProtocolError(f"{what}: answer of {len(pdu)} bytes for {count} registers")
    return list(struct.unpack(f">{count}H", pdu[2:]))


def parse_write_response(pdu: bytes, address: int, count: int, what: str) -> None:
    """Checks an FC 16 response echoes start and quantity."""
    _check_exception(pdu, 16, what)
    if len(pdu) != 5 or struct.unpack(">HH", pdu[1:5]) != (address, count):
        raise ProtocolError(f"{what}: confirmation {pdu.hex()} does not match the request")
