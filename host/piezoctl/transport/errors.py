"""Transport errors: each is a :class:`piezoctl.errors.CliError`, printed by the
CLI as one line naming the port and what went wrong."""

from __future__ import annotations

from ..errors import CliError, ConnectionFailed, ControllerRefused

__all__ = ["TransportError", "PortSpecError", "PortUnreachableError",
           "TransportTimeoutError", "ModbusExceptionError", "ProtocolError",
           "EXCEPTION_NAMES"]

# Modbus Application Protocol V1.1b3, section 7.
EXCEPTION_NAMES = {
    0x01: "illegal function",
    0x02: "illegal data address",
    0x03: "illegal data value",
    0x04: "server device failure",
    0x05: "acknowledge",
    0x06: "server device busy",
    0x08: "memory parity error",
    0x0A: "gateway path unavailable",
    0x0B: "gateway target device failed to respond",
}


class TransportError(CliError):
    """Any failure to talk to the controller."""


class PortSpecError(TransportError):
    """A PORT string that is not tcp:HOST:PORT, rtu:DEVICE[:BAUD] or usb[:VID:PID]."""


class PortUnreachableError(TransportError, ConnectionFailed):
    """The port cannot be opened: no such device, connection refused, no USB device."""


class TransportTimeoutError(TransportError, ConnectionFailed):
    """No (complete, valid) answer within the timeout."""


class ProtocolError(TransportError, ConnectionFailed):
    """An answer that does not fit the request (wrong function, length, sequence):
    the link or what answers on it cannot be trusted (exit 5, like no answer)."""


class ModbusExceptionError(TransportError, ControllerRefused):
    """The controller answered with a Modbus exception response.

    ``code`` is the exception code (1 illegal function, 2 illegal data address,
    3 illegal data value, 4 server device failure, ...), ``name`` its name.
    """

    def __init__(self, message: str, code: int, function: int):
        super().__init__(message)
        self.code = code
        self.function = function
        self.name = EXCEPTION_NAMES.get(code, "unknown exception")


def exception_text(code: int) -> str:
    """``"illegal data address (exception 02)"``."""
    return f"{EXCEPTION_NAMES.get(code, 'unknown exception')} (exception {code:02X})"
