"""The register client every transport returns: reads, chunked writes, one
write-then-read request and 32-bit helpers over the primitive Modbus requests.

32-bit values take two registers, high word first (common/interface.toml).
They are packed here with integer arithmetic, not by a library's float or
word-order helpers (see STYLE.md on libmodbus 3.1.6's float helpers).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .. import interface

__all__ = ["RegisterClient", "u32_to_regs", "regs_to_u32", "i32_to_regs", "regs_to_i32",
           "MAX_READ", "MAX_WRITE", "MAX_RW_WRITE"]

MAX_READ = interface.MODBUS_MAX_READ_REGISTERS    # 125, Modbus AP v1.1b3 6.3
MAX_WRITE = interface.MODBUS_MAX_WRITE_REGISTERS  # 123, Modbus AP v1.1b3 6.12
MAX_RW_WRITE = 121  # FC 23 write quantity, Modbus AP v1.1b3 6.17 (the request fits 253 bytes)


def u32_to_regs(value: int) -> list[int]:
    """``[high, low]`` words of an unsigned 32-bit value."""
    if not 0 <= value <= 0xFFFF_FFFF:
        raise ValueError(f"{value} does not fit 32 bits unsigned")
    return [(value >> 16) & 0xFFFF, value & 0xFFFF]


def regs_to_u32(regs: Sequence[int]) -> int:
    """Unsigned 32-bit value of ``[high, low]``."""
    hi, lo = regs
    return ((hi & 0xFFFF) << 16) | (lo & 0xFFFF)


def i32_to_regs(value: int) -> list[int]:
    """``[high, low]`` words of a signed 32-bit value (two's complement)."""
    if not -0x8000_0000 <= value <= 0x7FFF_FFFF:
        raise ValueError(f"{value} does not fit 32 bits signed")
    return u32_to_regs(value & 0xFFFF_FFFF)


def regs_to_i32(regs: Sequence[int]) -> int:
    """Signed 32-bit value of ``[high, low]``."""
    v = regs_to_u32(regs)
    return v - 0x1_0000_0000 if v & 0x8000_0000 else v


def _check_span(address: int, count: int) -> None:
    if not 0 <= address <= 0xFFFF or count < 0 or address + count > 0x10000:
        raise ValueError(f"registers {address}+{count} are outside the 16-bit address space")


class RegisterClient:
    """Input/holding register access of one controller.

    Subclasses implement ``_read(function, address, count)`` (function 3 or 4,
    ``count <= 125``) and ``_write(address, values)`` (``len(values) <= 123``)
    and raise :mod:`piezoctl.transport.errors` exceptions; they may implement
    ``_read_write`` (FC 23), which otherwise takes an FC 16 and an FC 3
    request. Longer reads and
    writes are split here into requests within the limits, in address order;
    a write that fails part-way raises after the chunks before it were written.
    """

    name = "port"

    # -- primitives (subclasses)
    def _read(self, function: int, address: int, count: int) -> list[int]:
        raise NotImplementedError

    def _write(self, address: int, values: list[int]) -> None:
        raise NotImplementedError

    def _read_write(self, read_address: int, read_count: int, write_address: int,
                    values: list[int]) -> list[int]:
        """FC 23 where the transport has it; here the same in two requests."""
        self._write(write_address, values)
        return self._read(3, read_address, read_count)

    def close(self) -> None:
        """Releases the port."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- registers
    def _read_chunked(self, function: int, address: int, count: int) -> list[int]:
        _check_span(address, count)
        out: list[int] = []
        while len(out) < count:
            n = min(MAX_READ, count - len(out))
            got = self._read(function, address + len(out), n)
            out.extend(got)
        return out

    def read_input(self, address: int, count: int = 1) -> list[int]:
        """Input registers (FC 4) ``address .. address + count - 1``."""
        return self._read_chunked(4, address, count)

    def read_holding(self, address: int, count: int = 1) -> list[int]:
        """Holding registers (FC 3) ``address .. address + count - 1``."""
        return self._read_chunked(3, address, count)

    def write_holding(self, address: int, values: Iterable[int]) -> None:
        """Writes holding registers from ``address`` on (FC 16), at most 123 per request."""
        vals = [int(v) for v in values]
        for v in vals:
            if not 0 <= v <= 0xFFFF:
                raise ValueError(f"register value {v} does not fit 16 bits")
        _check_span(address, len(vals))
        for off in range(0, len(vals), MAX_WRITE):
            self._write(address + off, vals[off:off + MAX_WRITE])

    def read_write(self, read_address: int, read_count: int, write_address: int,
                   values: Iterable[int]) -> list[int]:
        """Writes holding registers from ``write_address`` on, then reads
        ``read_count`` holding registers from ``read_address``: one FC 23
        request (Modbus AP 6.17: the write is done before the read), at most
        121 written and 125 read. A refused write raises and reads nothing."""
        vals = [int(v) for v in values]
        for v in vals:
            if not 0 <= v <= 0xFFFF:
                raise ValueError(f"register value {v} does not fit 16 bits")
        if not 1 <= len(vals) <= MAX_RW_WRITE or not 1 <= read_count <= MAX_READ:
            raise ValueError(f"read/write of {read_count} read and {len(vals)} written registers: "
                             f"FC 23 carries 1..{MAX_READ} and 1..{MAX_RW_WRITE}")
        _check_span(write_address, len(vals))
        _check_span(read_address, read_count)
        return self._read_write(read_address, read_count, write_address, vals)

    # -- 32-bit values, high word first
    def read_input_u32(self, address: int) -> int:
        return regs_to_u32(self.read_input(address, 2))

    def read_holding_u32(self, address: int) -> int:
        return regs_to_u32(self.read_holding(address, 2))

    def read_input_i32(self, address: int) -> int:
        return regs_to_i32(self.read_input(address, 2))

    def read_holding_i32(self, address: int) -> int:
        return regs_to_i32(self.read_holding(address, 2))

    def write_holding_u32(self, address: int, value: int) -> None:
        self.write_holding(address, u32_to_regs(value))

    def write_holding_i32(self, address: int, value: int) -> None:
        self.write_holding(address, i32_to_regs(value))
