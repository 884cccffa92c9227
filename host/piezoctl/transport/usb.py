"""Modbus PDUs over USB vendor-class bulk endpoints, through pyusb.

Framing (docs/protocol.md, firmware/protocol/usb_bulk.h): each transfer is a
4-byte header -- magic 0xA5, sequence number, PDU length (little-endian) --
and one PDU. The host picks the sequence number (incremented per request);
an answer with another number is a stale answer to an earlier, timed-out
request and is skipped.
"""

from __future__ import annotations

import struct

from .. import interface
from .client import RegisterClient
from .errors import PortUnreachableError, ProtocolError, TransportTimeoutError
from .pdu import parse_read_response, parse_write_response, read_request, write_request
from .spec import PortSpec

__all__ = ["UsbClient", "DEFAULT_VID", "DEFAULT_PID", "MAGIC", "frame", "unframe"]

# pid.codes' open-source vendor id with its test product id: to be replaced by
# a product id assigned to piezoctl.
DEFAULT_VID = 0x1209
DEFAULT_PID = 0x0001
MAGIC = 0xA5
HEADER = 4
PDU_MAX = 253
VENDOR_CLASS = 0xFF

_FUNCTION_NAMES = {3: "read holding", 4: "read input", 16: "write holding"}


def read_write_request(read_address: int, read_count: int, write_address: int,
                       values: list[int]) -> bytes:
    """FC 23 [AP 6.17]: function, read start, read quantity, write start,
    write quantity, byte count, values (big-endian)."""
    n = len(values)
    return struct.pack(f">BHHHHB{n}H", 23, read_address, read_count, write_address, n, 2 * n,
                       *values)


def frame(seq: int, pdu: bytes) -> bytes:
    """Header + PDU."""
    if not 1 <= len(pdu) <= PDU_MAX:
        raise ValueError(f"PDU of {len(pdu)} bytes")
    return struct.pack("<BBH", MAGIC, seq & 0xFF, len(pdu)) + pdu


def unframe(data: bytes) -> tuple[int, bytes]:
    """``(seq, pdu)`` of a transfer; raises :class:`ProtocolError` if malformed."""
    if len(data) < HEADER:
        raise ProtocolError(f"USB answer of {len(data)} bytes, shorter than its header")
    magic, seq, n = struct.unpack("<BBH", data[:HEADER])
    if magic != MAGIC or n != len(data) - HEADER or not 1 <= n <= PDU_MAX:
        raise ProtocolError(f"malformed USB answer {bytes(data[:16]).hex()}...")
    return seq, bytes(data[HEADER:])


def _find_endpoints(dev):
    import usb.util

    for cfg in dev:
        for intf in cfg:
            if intf.bInterfaceClass != VENDOR_CLASS:
                continue
            ep_out = usb.util.find_descriptor(intf, custom_match=lambda e: (
                usb.util.endpoint_direction(e.bEndpointAddress) == usb.util.ENDPOINT_OUT
                and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK))
            ep_in = usb.util.find_descriptor(intf, custom_match=lambda e: (
                usb.util.endpoint_direction(e.bEndpointAddress) == usb.util.ENDPOINT_IN
                and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK))
            if ep_out is not None and ep_in is not None:
                return cfg, intf, ep_out, ep_in
    return None


class UsbClient(RegisterClient):
    """A controller on USB: the first device with the VID:PID and a vendor-class
    interface with a bulk OUT and a bulk IN endpoint."""

    def __init__(self, spec: PortSpec, *, timeout: float = 1.0, backend=None):
        import usb.core

        self.name = spec.text
        self.timeout_ms = max(1, int(timeout * 1000))
        self._seq = 0
        try:
            dev = usb.core.find(idVendor=spec.vid, idProduct=spec.pid, backend=backend)
        except usb.core.NoBackendError:
            raise PortUnreachableError(f"{self.name}: no libusb backend for pyusb") from None
        except usb.core.USBError as exc:
            raise PortUnreachableError(f"{self.name}: cannot enumerate USB devices ({exc})") from None
        if dev is None:
            raise PortUnreachableError(
                f"{self.name}: no USB device {spec.vid:04x}:{spec.pid:04x}")
        found = _find_endpoints(dev)
        if found is None:
            raise PortUnreachableError(
                f"{self.name}: device {spec.vid:04x}:{spec.pid:04x} has no vendor-class "
                f"interface with bulk endpoints")
        cfg, intf, self._ep_out, self._ep_in = found
        self._dev = dev
        self._intf = intf.bInterfaceNumber
        try:
            if dev.get_active_configuration().bConfigurationValue != cfg.bConfigurationValue:
                dev.set_configuration(cfg.bConfigurationValue)
        except usb.core.USBError:
            try:
                dev.set_configuration(cfg.bConfigurationValue)
            except usb.core.USBError as exc:
                raise PortUnreachableError(f"{self.name}: cannot configure the device ({exc})") from None

    def close(self) -> None:
        import usb.util

        usb.util.dispose_resources(self._dev)

    def transact(self, pdu: bytes, what: str) -> bytes:
        """Sends one request PDU and returns the answer PDU."""
        import usb.core

        self._seq = (self._seq + 1) & 0xFF
        seq = self._seq
        try:
            self._dev.write(self._ep_out.bEndpointAddress, frame(seq, pdu), self.timeout_ms)
            while True:
                data = self._dev.read(self._ep_in.bEndpointAddress, HEADER + PDU_MAX,
                                      self.timeout_ms)
                got_seq, answer = unframe(bytes(data))
                if got_seq == seq:
                    return answer
        except usb.core.USBTimeoutError:
            raise TransportTimeoutError(f"{what}: no answer within the timeout") from None
        except usb.core.USBError as exc:
            raise PortUnreachableError(f"{what}: USB error ({exc})") from None

    def _read(self, function: int, address: int, count: int) -> list[int]:
        what = f"{self.name}: {_FUNCTION_NAMES[function]} {address:#06x}+{count}"
        pdu = self.transact(read_request(function, address, count), what)
        return parse_read_response(pdu, function, count, what)

    def _write(self, address: int, values: list[int]) -> None:
        what = f"{self.name}: write holding {address:#06x}+{len(values)}"
        pdu = self.transact(write_request(address, values), what)
        parse_write_response(pdu, address, len(values), what)

    def _read_write(self, read_address: int, read_count: int, write_address: int,
                    values: list[int]) -> list[int]:
        what = (f"{self.name}: read/write holding {read_address:#06x}+{read_count}, "
                f"{write_address:#06x}+{len(values)}")
        pdu = self.transact(read_write_request(read_address, read_count, write_address, values), what)
        return parse_read_response(pdu, 23, read_count, what)
