"""piezoctl.transport without a controller: PORT strings, chunking to the
Modbus limits, 32-bit packing, the USB framing and PDU codec, and the errors
for ports that cannot be reached."""

from __future__ import annotations

import socket
import struct

import pytest

from piezoctl import interface
from piezoctl.errors import CliError
from piezoctl.transport import (MAX_READ, MAX_WRITE, ModbusExceptionError, PortSpecError,
                                PortUnreachableError, ProtocolError, RegisterClient,
                                TransportError, i32_to_regs, open_port, parse_port,
                                regs_to_i32, regs_to_u32, u32_to_regs)
from piezoctl.transport import pdu, usb


# ---------------------------------------------------------------- PORT strings
@pytest.mark.parametrize("text, fields", [
    ("tcp:127.0.0.1:5020", dict(kind="tcp", host="127.0.0.1", port=5020)),
    ("tcp:stage.lab", dict(kind="tcp", host="stage.lab", port=502)),
    ("TCP:h:1", dict(kind="tcp", host="h", port=1)),
    ("tcp:[::1]:65535", dict(kind="tcp", host="::1", port=65535)),
    ("tcp:[fe80::1]", dict(kind="tcp", host="fe80::1", port=502)),
    ("rtu:/dev/ttyUSB0", dict(kind="rtu", device="/dev/ttyUSB0", baud=19200, parity="E")),
    ("rtu:/dev/ttyACM1:115200", dict(kind="rtu", device="/dev/ttyACM1", baud=115200, parity="E")),
    ("rtu:COM3:9600:n", dict(kind="rtu", device="COM3", baud=9600, parity="N")),
    ("rtu:/dev/pts/7:38400:O", dict(kind="rtu", device="/dev/pts/7", baud=38400, parity="O")),
    ("usb", dict(kind="usb", vid=usb.DEFAULT_VID, pid=usb.DEFAULT_PID)),
    ("usb:1209:0001", dict(kind="usb", vid=0x1209, pid=0x0001)),
    ("usb:0x16c0:05DC", dict(kind="usb", vid=0x16C0, pid=0x05DC)),
])
def test_parse_port(text, fields):
    spec = parse_port(text)
    assert spec.text == text
    for k, v in fields.items():
        assert getattr(spec, k) == v, k


@pytest.mark.parametrize("text, why", [
    ("", "empty"),
    ("tcp", "no host"),
    ("tcp:", "no host"),
    ("tcp::502", "no host"),
    ("tcp:h:", "TCP port '' is not a number"),
    ("tcp:h:0", "TCP port 0 is outside 1..65535"),
    ("tcp:h:65536", "outside"),
    ("tcp:h:http", "'http' is not a number"),
    ("tcp:fe80::1:502", "IPv6 address in []"),
    ("tcp:[::1", "unterminated"),
    ("tcp:[::1]x", "unexpected 'x'"),
    ("rtu", "no serial device"),
    ("rtu::9600", "no serial device"),
    ("rtu:/dev/ttyS0:fast", "baud rate 'fast'"),
    ("rtu:/dev/ttyS0:0", "outside"),
    ("rtu:/dev/ttyS0:9600:X", "parity 'X'"),
    ("rtu:/dev/ttyS0:9600:N:1", "too many fields"),
    ("usb:1209", "VID:PID"),
    ("usb:1209:0001:2", "VID:PID"),
    ("usb:xyz:0001", "vendor id 'xyz'"),
    ("usb:1209:10000", "outside"),
    ("serial:/dev/ttyS0", "unknown transport 'serial'"),
    ("/dev/ttyUSB0", "unknown transport"),
])
def test_parse_port_refuses_with_reason(text, why):
    with pytest.raises(PortSpecError) as info:
        parse_port(text)
    msg = str(info.value)
    assert why in msg
    assert repr(text) in msg and "tcp:HOST:PORT" in msg
    assert isinstance(info.value, CliError)


# ---------------------------------------------------------------- chunking
class Recorder(RegisterClient):
    """Primitive requests recorded against a 64 Ki-register memory; each
    primitive also asserts the per-request limits."""

    def __init__(self, fail_at=None):
        self.mem = {3: [0] * 0x10000, 4: [(7 * a) & 0xFFFF for a in range(0x10000)]}
        self.calls = []
        self.fail_at = fail_at

    def _read(self, function, address, count):
        assert function in (3, 4) and 1 <= count <= 125
        self.calls.append(("r", function, address, count))
        return self.mem[function][address:address + count]

    def _write(self, address, values):
        assert 1 <= len(values) <= 123
        if self.fail_at is not None and address <= self.fail_at < address + len(values):
            raise ModbusExceptionError("refused", 2, 16)
        self.calls.append(("w", address, len(values)))
        self.mem[3][address:address + len(values)] = values


def test_limits_come_from_the_interface():
    assert MAX_READ == interface.MODBUS_MAX_READ_REGISTERS == 125
    assert MAX_WRITE == interface.MODBUS_MAX_WRITE_REGISTERS == 123


@pytest.mark.parametrize("n, chunks", [
    (1, [1]), (123, [123]), (124, [123, 1]), (246, [123, 123]), (247, [123, 123, 1]),
    (1000, [123] * 8 + [16]),
])
def test_writes_are_chunked_to_123(n, chunks):
    c = Recorder()
    values = [(i * 31 + 5) & 0xFFFF for i in range(n)]
    c.write_holding(0x2010, values)
    assert [k[2] for k in c.calls] == chunks
    assert [k[1] for k in c.calls] == [0x2010 + 123 * i for i in range(len(chunks))]
    assert c.mem[3][0x2010:0x2010 + n] == values
    assert c.mem[3][0x2010 + n] == 0


@pytest.mark.parametrize("n, chunks", [(1, [1]), (125, [125]), (126, [125, 1]), (300, [125, 125, 50])])
def test_reads_are_chunked_to_125(n, chunks):
    c = Recorder()
    got = c.read_input(0x100, n)
    assert got == [(7 * a) & 0xFFFF for a in range(0x100, 0x100 + n)]
    assert [k[3] for k in c.calls] == chunks
    assert all(k[1] == 4 for k in c.calls)
    c.calls.clear()
    c.mem[3][0x10:0x10 + n] = list(range(n))
    assert c.read_holding(0x10, n) == list(range(n))
    assert all(k[1] == 3 for k in c.calls)


def test_empty_write_sends_nothing_and_bad_values_are_refused_before_sending():
    c = Recorder()
    c.write_holding(0x1000, [])
    assert c.calls == []
    for bad in ([0x10000], [-1], [1, 2, 70000]):
        with pytest.raises(ValueError):
            c.write_holding(0x1000, bad)
    with pytest.raises(ValueError):
        c.write_holding(0xFFFF, [1, 2])  # past the address space
    with pytest.raises(ValueError):
        c.read_holding(0xFF84, 125)
    assert c.calls == []


def test_failed_chunk_stops_the_write():
    c = Recorder(fail_at=0x2000 + 200)
    with pytest.raises(ModbusExceptionError):
        c.write_holding(0x2000, [1] * 300)
    assert c.calls == [("w", 0x2000, 123)]


# ---------------------------------------------------------------- 32-bit values
@pytest.mark.parametrize("value, regs", [
    (0, [0, 0]), (1, [0, 1]), (0x10000, [1, 0]), (0x12345678, [0x1234, 0x5678]),
    (0xFFFFFFFF, [0xFFFF, 0xFFFF]), (0x36D4A9EA, [0x36D4, 0xA9EA]),
])
def test_u32_high_word_first(value, regs):
    assert u32_to_regs(value) == regs
    assert regs_to_u32(regs) == value


@pytest.mark.parametrize("value, regs", [
    (-1, [0xFFFF, 0xFFFF]), (-2, [0xFFFF, 0xFFFE]), (-0x80000000, [0x8000, 0]),
    (0x7FFFFFFF, [0x7FFF, 0xFFFF]), (-65536, [0xFFFF, 0]),
])
def test_i32_twos_complement(value, regs):
    assert i32_to_regs(value) == regs
    assert regs_to_i32(regs) == value


def test_32bit_range_checks_and_client_helpers():
    for bad in (-1, 1 << 32):
        with pytest.raises(ValueError):
            u32_to_regs(bad)
    for bad in (-(1 << 31) - 1, 1 << 31):
        with pytest.raises(ValueError):
            i32_to_regs(bad)
    c = Recorder()
    c.write_holding_u32(interface.HOLDING_REGISTERS["table_offset"][0], 0x00012345)
    assert c.mem[3][0x2000:0x2002] == [0x0001, 0x2345]
    assert c.read_holding_u32(0x2000) == 0x12345
    c.write_holding_i32(0x2000, -3)
    assert c.read_holding_i32(0x2000) == -3
    assert c.mem[3][0x2000:0x2002] == [0xFFFF, 0xFFFD]
    assert c.read_input_u32(2) == (14 << 16) | 21
    assert c.read_input_i32(0x9362) == regs_to_i32([(7 * 0x9362) & 0xFFFF, (7 * 0x9363) & 0xFFFF])


# ---------------------------------------------------------------- PDUs and USB frames
def test_pdu_requests_are_modbus_bytes():
    assert pdu.read_request(3, 0x1000, 2) == bytes([3, 0x10, 0x00, 0x00, 0x02])
    assert pdu.read_request(4, 0x0000, 125) == bytes([4, 0, 0, 0, 125])
    assert pdu.write_request(0x2010, [0x1234, 0xABCD]) == bytes(
        [16, 0x20, 0x10, 0, 2, 4, 0x12, 0x34, 0xAB, 0xCD])
    assert len(pdu.write_request(0, [0] * 123)) == 252


def test_pdu_responses_and_named_exceptions():
    assert pdu.parse_read_response(bytes([4, 4, 0x50, 0x5A, 0, 1]), 4, 2, "x") == [0x505A, 1]
    pdu.parse_write_response(bytes([16, 0x20, 0x10, 0, 2]), 0x2010, 2, "x")
    with pytest.raises(ModbusExceptionError) as info:
        pdu.parse_read_response(bytes([0x83, 0x02]), 3, 1, "usb: read holding 0x1000+1")
    e = info.value
    assert (e.code, e.function, e.name) == (2, 3, "illegal data address")
    assert str(e) == "usb: read holding 0x1000+1: illegal data address (exception 02)"
    for code, name in [(1, "illegal function"), (3, "illegal data value"),
                       (4, "server device failure"), (0x0B, "gateway target device failed to respond"),
                       (0x55, "unknown exception")]:
        with pytest.raises(ModbusExceptionError, match=name):
            pdu.parse_write_response(bytes([0x90, code]), 0, 1, "x")
    for bad in (b"", bytes([4, 2, 0]), bytes([4, 4, 0, 1]), bytes([3, 2, 0, 1]),
                bytes([0x84, 2, 0]), bytes([0x84])):
        with pytest.raises(ProtocolError):
            pdu.parse_read_response(bad, 4, 1 if len(bad) != 6 else 2, "x")
    with pytest.raises(ProtocolError):
        pdu.parse_write_response(bytes([16, 0x20, 0x11, 0, 2]), 0x2010, 2, "x")


def test_usb_frames():
    f = usb.frame(0x37, bytes([4, 0, 0, 0, 2]))
    assert f == bytes([0xA5, 0x37, 5, 0, 4, 0, 0, 0, 2])
    assert usb.frame(256 + 3, b"\x03")[1] == 3
    assert usb.unframe(bytes([0xA5, 9, 2, 0, 0x83, 2])) == (9, bytes([0x83, 2]))
    big = usb.frame(1, bytes(253))
    assert big[2:4] == struct.pack("<H", 253) and usb.unframe(big) == (1, bytes(253))
    for bad in (b"", bytes([0xA5, 1, 1]), bytes([0xA4, 1, 1, 0, 3]), bytes([0xA5, 1, 2, 0, 3]),
                bytes([0xA5, 1, 0, 0])):
        with pytest.raises(ProtocolError):
            usb.unframe(bad)
    with pytest.raises(ValueError):
        usb.frame(1, b"")
    with pytest.raises(ValueError):
        usb.frame(1, bytes(254))


# ---------------------------------------------------------------- unreachable ports
def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_tcp_port_is_a_clear_error():
    port = free_tcp_port()  # closed again: nothing listens there
    with pytest.raises(PortUnreachableError, match=f"tcp:127.0.0.1:{port}: cannot connect"):
        open_port(f"tcp:127.0.0.1:{port}", timeout=0.3)


def test_missing_serial_device_is_a_clear_error(tmp_path):
    dev = tmp_path / "ttyNOPE"
    with pytest.raises(PortUnreachableError, match="cannot open serial device"):
        open_port(f"rtu:{dev}:9600", timeout=0.3)


def test_absent_usb_device_is_a_clear_error():
    # This machine has no USB bus; with or without a libusb backend the answer
    # is an unreachable port, never a traceback.
    with pytest.raises(PortUnreachableError, match="usb:1209:7fff"):
        open_port("usb:1209:7fff", timeout=0.3)


def test_errors_are_cli_errors():
    for cls in (PortSpecError, PortUnreachableError, ModbusExceptionError, ProtocolError):
        assert issubclass(cls, TransportError) and issubclass(cls, CliError)


class LateServer:
    """A Modbus TCP server (FC 16 only) on a thread that answers its first request
    ``late_s`` [s] late, as a controller stalled on a loaded machine does, and
    counts the requests that reach it."""

    def __init__(self, late_s: float):
        import threading
        self.late_s = late_s
        self.requests = []
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(1)
        self.port = self.sock.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        import time
        conn, _ = self.sock.accept()
        conn.settimeout(10.0)
        buf = b""
        try:
            while True:
                while len(buf) < 7 or len(buf) < 6 + struct.unpack(">H", buf[4:6])[0]:
                    chunk = conn.recv(4096)
                    if not chunk:
                        return
                    buf += chunk
                n = 6 + struct.unpack(">H", buf[4:6])[0]
                req, buf = buf[:n], buf[n:]
                self.requests.append(req)
                if len(self.requests) == 1:
                    time.sleep(self.late_s)
                tid, unit, fc, addr, count = struct.unpack(">HxxxxBBHH", req[:12])
                conn.sendall(struct.pack(">HHHBBHH", tid, 0, 6, unit, fc, addr, count))
        except OSError:
            return
        finally:
            conn.close()


def test_a_late_tcp_answer_is_waited_for_and_the_request_never_sent_twice():
    # round 18: pymodbus sent a request again after 1 s without an answer (retries=1); a controller
    # stalled that long executed it twice (a start_wave: the learning trial's wave restarted mid-record)
    from piezoctl.transport import open_port
    srv = LateServer(late_s=1.6)
    c = open_port(f"tcp:127.0.0.1:{srv.port}", timeout=1.0)
    try:
        c.write_holding(4100, [7])
        c.write_holding(4100, [8])
    finally:
        c.close()
    srv.thread.join(5.0)
    # each write reached the controller exactly once, in order
    assert [struct.unpack(">H", r[13:15])[0] for r in srv.requests] == [7, 8]
