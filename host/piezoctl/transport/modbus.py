"""Modbus TCP and RTU through pymodbus (3.x: the unit is ``device_id=``;
pinned to pymodbus 3.16.1 in host/requirements.lock)."""

from __future__ import annotations

import time

from .. import interface
from .client import RegisterClient
from .errors import (ModbusExceptionError, PortUnreachableError, ProtocolError,
                     TransportTimeoutError, exception_text)
from .spec import PortSpec

__all__ = ["PymodbusClient"]

_FUNCTION_NAMES = {3: "read holding", 4: "read input", 16: "write holding",
                   23: "read/write holding"}

# Over TCP a request is sent once and its answer waited for at least this long [s]. TCP
# delivers the request or the connection fails, so sending it again after a timeout
# never recovers a lost one: it only makes the controller execute it twice. Until
# round 18 pymodbus did so after 1 s without an answer (retries=1): a controller that
# stalled for a second (the SIL controller on a loaded machine) ran a command such as
# start_wave twice, and a learning trial restarted its wave mid-record
# (docs/calibrate.md, "Round 18").
TCP_ANSWER_MIN_S = 5.0


class PymodbusClient(RegisterClient):
    """A controller behind a pymodbus TCP or RTU client."""

    def __init__(self, spec: PortSpec, *, unit: int = interface.MODBUS_UNIT_ID,
                 timeout: float = 1.0, retries: int = 1):
        """``timeout`` [s] per answer; ``retries``: times a request without an answer is sent
        again on RTU (a frame the line lost). Over TCP a request is never sent again and its
        answer is waited for ``max(timeout, TCP_ANSWER_MIN_S)``."""
        from pymodbus.client import ModbusSerialClient, ModbusTcpClient
        from pymodbus import FramerType

        self.name = spec.text
        self.unit = unit
        self._tcp = spec.kind == "tcp"
        self._last_ok = time.monotonic()
        self.reconnects = 0
        if spec.kind == "tcp":
            self._client = ModbusTcpClient(spec.host, port=spec.port,
                                           timeout=max(timeout, TCP_ANSWER_MIN_S), retries=0)
        elif spec.kind == "rtu":
            self._client = ModbusSerialClient(spec.device, framer=FramerType.RTU,
                                              baudrate=spec.baud, parity=spec.parity,
                                              bytesize=8, stopbits=1, timeout=timeout,
                                              retries=retries)
        else:
            raise ValueError(f"pymodbus does not carry {spec.kind!r}")
        if not self._client.connect():
            what = (f"cannot connect to {spec.host}:{spec.port} (host unreachable or no Modbus TCP server there)"
                    if spec.kind == "tcp" else f"cannot open serial device {spec.device}")
            raise PortUnreachableError(f"{self.name}: {what}")

    def close(self) -> None:
        self._client.close()

    def _call(self, function: int, address: int, count: int, call):
        from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

        what = f"{self.name}: {_FUNCTION_NAMES[function]} {address:#06x}+{count}"
        try:
            try:
                rsp = call()
            except ConnectionException:
                # The controller closes a TCP connection that was idle (its
                # idle timeout, or a new client taking the slot: docs/protocol.md);
                # the request never reached it. Connect again and send it once
                # more. The new connection is a new session: locked, no upload.
                idle_s = interface.MODBUS_TCP["evict_min_idle_ms"] / 1000.0
                if not self._tcp or time.monotonic() - self._last_ok < idle_s:
                    raise
                self._client.close()
                if not self._client.connect():
                    raise
                self.reconnects += 1
                rsp = call()
        except ConnectionException as exc:
            raise PortUnreachableError(f"{what}: connection lost ({exc})") from None
        except ModbusIOException:
            raise TransportTimeoutError(f"{what}: no answer within the timeout") from None
        except ModbusException as exc:
            raise ProtocolError(f"{what}: {exc}") from None
        self._last_ok = time.monotonic()
        if rsp.isError():
            code = getattr(rsp, "exception_code", None)
            if code is None:
                raise ProtocolError(f"{what}: error response {rsp}")
            raise ModbusExceptionError(f"{what}: {exception_text(code)}", code, function)
        return rsp

    def _read(self, function: int, address: int, count: int) -> list[int]:
        c = self._client
        fn = c.read_holding_registers if function == 3 else c.read_input_registers
        rsp = self._call(function, address, count,
                         lambda: fn(address, count=count, device_id=self.unit))
        regs = list(rsp.registers)
        if len(regs) != count:
            raise ProtocolError(f"{self.name}: asked {count} registers at {address:#06x}, "
                                f"got {len(regs)}")
        return regs

    def _write(self, address: int, values: list[int]) -> None:
        rsp = self._call(16, address, len(values),
                         lambda: self._client.write_registers(address, values,
                                                              device_id=self.unit))
        if (rsp.address, rsp.count) != (address, len(values)):
            raise ProtocolError(f"{self.name}: write of {len(values)} registers at "
                                f"{address:#06x} confirmed as {rsp.count} at {rsp.address:#06x}")

    def _read_write(self, read_address: int, read_count: int, write_address: int,
                    values: list[int]) -> list[int]:
        rsp = self._call(23, read_address, read_count,
                         lambda: self._client.readwrite_registers(
                             read_address=read_address, read_count=read_count,
                             write_address=write_address, values=values, device_id=self.unit))
        regs = list(rsp.registers)
        if len(regs) != read_count:
            raise ProtocolError(f"{self.name}: asked {read_count} registers at {read_address:#06x} "
                                f"(FC 23), got {len(regs)}")
        return regs
