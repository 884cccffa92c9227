"""Interop over a pseudo-terminal and TCP: pymodbus's clients (through
piezoctl.transport) against the firmware's protocol layer.

RTU: tests/firmware/rtu_pty_server runs the firmware's RTU framer and PDU
server behind a pty (openpty); pymodbus's serial client opens the slave side.
TCP: tests/firmware/tcp_modbus_server runs the libmodbus-based server loop on
127.0.0.1 at a free port. Both serve the test register bank of
tests/firmware/test_modbus_regs.h (addresses and values used below).

The servers come from a CMake build directory: $PIEZO_BUILD_DIR, build/sil or
build/proto; a configured directory without them gets them built.
"""

from __future__ import annotations

import os
import pathlib
import subprocess

import pytest

from piezoctl.transport import (ModbusExceptionError, PortUnreachableError,
                                TransportTimeoutError, open_port)

ROOT = pathlib.Path(__file__).resolve().parents[2]

# tests/firmware/test_modbus_regs.h
INPUT_N = 0x200
HOLD_B = 0x2000
MODE = 0x1001
FAULT = 0x10FE


def input_value(a: int) -> int:
    return 0x505A if a == 0 else (0x4000 + 3 * a) & 0xFFFF


def find_server(name: str) -> pathlib.Path:
    dirs = [pathlib.Path(os.environ["PIEZO_BUILD_DIR"])] if os.environ.get("PIEZO_BUILD_DIR") else []
    dirs += [ROOT / "build" / "sil", ROOT / "build" / "proto"]
    for d in dirs:
        exe = d / "tests" / "firmware" / name
        if exe.is_file():
            return exe
    for d in dirs:
        if (d / "CMakeCache.txt").is_file():
            subprocess.run(["cmake", "--build", str(d), "--target", name, "-j2"], check=True,
                           stdout=subprocess.DEVNULL)
            exe = d / "tests" / "firmware" / name
            if exe.is_file():
                return exe
    pytest.skip(f"{name} is not built (configure build/sil: cmake --preset sil)")


class Server:
    def __init__(self, exe: pathlib.Path, *args: str):
        self.proc = subprocess.Popen([str(exe), *args], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.line = self.proc.stdout.readline().strip()
        assert self.line, self.proc.stderr.read()

    def stop(self) -> str:
        self.proc.stdin.close()
        self.proc.wait(timeout=10)
        err = self.proc.stderr.read()
        self.proc.stdout.close()
        self.proc.stderr.close()
        assert self.proc.returncode == 0, err
        return err


@pytest.fixture(scope="module")
def rtu_server():
    srv = Server(find_server("rtu_pty_server"), "--baud", "9600")
    yield srv
    stats = srv.stop()
    # every frame pymodbus sent was a valid frame for the framer
    assert "crc_errors 0 malformed 0" in stats, stats


@pytest.fixture(scope="module")
def tcp_server():
    srv = Server(find_server("tcp_modbus_server"))
    yield srv
    srv.stop()


@pytest.fixture(params=["rtu", "tcp"])
def port(request):
    if request.param == "rtu":
        srv = request.getfixturevalue("rtu_server")
        return f"rtu:{srv.line}:9600:N"
    srv = request.getfixturevalue("tcp_server")
    return f"tcp:127.0.0.1:{srv.line}"


def test_read_input_registers(port):
    with open_port(port, timeout=1.0) as c:
        assert c.read_input(0, 7) == [input_value(a) for a in range(7)]
        # 300 registers: three requests (125, 125, 50)
        assert c.read_input(0x40, 300) == [input_value(a) for a in range(0x40, 0x40 + 300)]


def test_chunked_write_and_read_back(port):
    values = [(0x9000 + 13 * i) & 0xFFFF for i in range(250)]
    with open_port(port) as c:
        c.write_holding(HOLD_B + 3, values)  # 123 + 123 + 4 registers
        got = c.read_holding(HOLD_B, 256)
        assert got[3:253] == values
        c.write_holding(HOLD_B, [0] * 256)  # back to zero for the other transport's run
        assert c.read_holding(HOLD_B, 256) == [0] * 256


def test_32bit_values_high_word_first(port):
    with open_port(port) as c:
        c.write_holding_u32(HOLD_B + 0x10, 0x36D4A9EA)
        assert c.read_holding(HOLD_B + 0x10, 2) == [0x36D4, 0xA9EA]
        assert c.read_holding_u32(HOLD_B + 0x10) == 0x36D4A9EA
        c.write_holding_i32(HOLD_B + 0x12, -123456)
        assert c.read_holding_i32(HOLD_B + 0x12) == -123456
        assert c.read_input_u32(1) == (input_value(1) << 16) | input_value(2)


@pytest.mark.parametrize("call, code, name", [
    (lambda c: c.read_holding(0x0000, 1), 2, "illegal data address"),
    (lambda c: c.read_input(INPUT_N - 1, 2), 2, "illegal data address"),
    (lambda c: c.write_holding(MODE, [9]), 3, "illegal data value"),
    (lambda c: c.read_holding(FAULT, 1), 4, "server device failure"),
    (lambda c: c.write_holding(FAULT - 1, [1, 2]), 4, "server device failure"),
])
def test_exceptions_are_named(port, call, code, name):
    with open_port(port) as c:
        with pytest.raises(ModbusExceptionError) as info:
            call(c)
        assert info.value.code == code
        assert info.value.name == name
        assert port in str(info.value) and f"{name} (exception {code:02X})" in str(info.value)
        # the server carries on, and a refused write changed nothing
        assert c.read_input(0, 1) == [0x505A]
        assert c.read_holding(MODE, 1) == [0]


def test_illegal_function_from_the_server(port):
    # FC 1 (read coils) is not supported by the firmware: exception 01
    with open_port(port) as c:
        rsp = c._client.read_coils(0, count=8, device_id=1)
        assert rsp.isError() and rsp.exception_code == 1


def test_wrong_unit_times_out_on_rtu(rtu_server):
    with open_port(f"rtu:{rtu_server.line}:9600:N", unit=7, timeout=0.3) as c:
        with pytest.raises(TransportTimeoutError, match="no answer within the timeout"):
            c.read_input(0, 1)
    with open_port(f"rtu:{rtu_server.line}:9600:N") as c:
        assert c.read_input(0, 1) == [0x505A]


def test_server_gone_is_unreachable(tmp_path):
    srv = Server(find_server("tcp_modbus_server"))
    port = srv.line
    srv.stop()
    with pytest.raises(PortUnreachableError):
        with open_port(f"tcp:127.0.0.1:{port}", timeout=0.3) as c:
            c.read_input(0, 1)
