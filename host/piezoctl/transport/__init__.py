"""Transports to the controller: ``open_port(PORT)`` returns a
:class:`RegisterClient` with ``read_input``, ``read_holding``,
``write_holding`` (chunked to 123 registers per request) and 32-bit helpers
(high word first).

PORT is ``tcp:HOST:PORT``, ``rtu:DEVICE[:BAUD[:PARITY]]`` or ``usb[:VID:PID]``
(:mod:`piezoctl.transport.spec`). Failures raise
:class:`~piezoctl.transport.errors.TransportError` subclasses (CLI errors):
:class:`PortSpecError`, :class:`PortUnreachableError`,
:class:`TransportTimeoutError`, :class:`ModbusExceptionError` (with the
exception's ``code`` and ``name``), :class:`ProtocolError`.
"""

from __future__ import annotations

from .. import interface
from .client import (MAX_READ, MAX_WRITE, RegisterClient, i32_to_regs, regs_to_i32,
                     regs_to_u32, u32_to_regs)
from .errors import (EXCEPTION_NAMES, ModbusExceptionError, PortSpecError,
                     PortUnreachableError, ProtocolError, TransportError,
                     TransportTimeoutError)
from .spec import PortSpec, parse_port

__all__ = ["open_port", "parse_port", "PortSpec", "RegisterClient", "MAX_READ", "MAX_WRITE",
           "u32_to_regs", "regs_to_u32", "i32_to_regs", "regs_to_i32", "EXCEPTION_NAMES",
           "TransportError", "PortSpecError", "PortUnreachableError",
           "TransportTimeoutError", "ModbusExceptionError", "ProtocolError"]


def open_port(spec: str | PortSpec, *, unit: int = interface.MODBUS_UNIT_ID,
              timeout: float = 1.0) -> RegisterClient:
    """Opens the controller at PORT; raises a TransportError naming the port
    when the string is malformed or the port cannot be opened.

    ``unit`` is the Modbus unit id (TCP and RTU), ``timeout`` seconds per answer.
    """
    ps = spec if isinstance(spec, PortSpec) else parse_port(spec)
    if ps.kind in ("tcp", "rtu"):
        from .modbus import PymodbusClient
        return PymodbusClient(ps, unit=unit, timeout=timeout)
    from .usb import UsbClient
    return UsbClient(ps, timeout=timeout)
