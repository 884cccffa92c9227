"""Table upload speed: upload + read-back verify + commit of the reference
table against the virtual controller (``tools/bench-upload``,
``docs/protocol.md`` "Speed").

The reference table is KP L = 10 + EUPI; the controller runs one feedforward
kind per image, so both images are measured -- ``kp_dcc`` (KP grid L = 10,
55 cells, DCC weights) and ``eupi_inverse`` (10 CPI + 10 x 3 UPI + 3 poly),
built by :mod:`piezoctl.fixtures.ctl` from the golden quantizers and
:mod:`piezoctl.tables.build` -- and their sum. One measurement of an image:

upload   ``Controller.upload_table`` (unlock, clear staged, one FC 16 per chunk)
verify   ``Controller.read_staged`` + byte compare + CRC
commit   ``Controller.commit_table`` and status polls until the controller
         reports the image's CRC as active (what ``piezoctl flash`` waits for)

Transports
    tcp   Modbus TCP on 127.0.0.1 (pymodbus client, sil-stage's server).
    rtu   Modbus RTU on sil-stage's pseudo-terminal. A pty has no baud rate,
          so :class:`PacedSerial` paces the line in real time: a request is
          delivered when its last character would have arrived (11 bits per
          character: 8 data bits, start, and 2 stop bits with no parity, the
          serial-line spec's framing; the pty refuses parity), answer bytes
          become readable one character time apart from when the server
          wrote them, and a request waits 3.5 character times (1.75 ms above
          19200 baud) after the last answer byte. The server's framer waits
          its own 3.5-character silence in real time. Pacing (rather than
          adding computed wire time afterwards) keeps the client's and
          server's own latencies overlapped with the line time as on a real
          line; the computed line occupancy is printed next to it.
    usb   pyusb under umockdev-run. umockdev replays a fixed script of bulk
          transfers, so the script is generated first: the same request
          sequence is run over Modbus TCP against sil-stage, i.e. the
          firmware's PDU server and register map compute every answer, and
          the (request, answer) PDUs are framed as the USB transport frames
          them (:func:`usb_script`). The replay then checks every OUT
          transfer byte for byte. Its time is the host stack plus umockdev's
          emulation of the kernel's usbdevfs, not a USB bus.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import select
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections import deque
from dataclasses import dataclass, field

from .. import interface
from ..device import WINDOW, Controller, REASON_NAMES
from ..fixtures.ctl import dcc_image, eupi_image
from ..sil.launch import VirtualController, sil_binary
from ..transport import open_port
from ..transport.client import RegisterClient
from ..transport.errors import ModbusExceptionError, ProtocolError
from ..transport.pdu import parse_read_response, parse_write_response, read_request, write_request
from ..transport.usb import frame, read_write_request

ROOT = pathlib.Path(__file__).resolve().parents[3]
GOALS_MS = {"tcp": 100.0, "rtu": 1000.0}
BITS_PER_CHAR = 11
USB_NODE = "/dev/bus/usb/001/002"
USB_DEVICE = ROOT / "tests" / "host" / "usb" / "piezoctl-1209-0001.umockdev"
USB_IN_LEN = 257  # the USB transport's read size: header + 253


def reference_images() -> list[tuple[str, bytes]]:
    """(name, image) of the reference table's two images."""
    return [("kp_dcc L=10", dcc_image()[0]), ("eupi_inverse", eupi_image()[0])]


def image_crc(img: bytes) -> int:
    return struct.unpack_from("<I", img, len(img) - 4)[0]


# ---------------------------------------------------------------- the sequence
@dataclass
class Phases:
    upload: float = 0.0
    verify: float = 0.0
    commit: float = 0.0
    requests: dict = field(default_factory=dict)

    @property
    def total(self) -> float:
        return self.upload + self.verify + self.commit


class RequestCounter:
    """Counts a client's primitive requests by function (wraps the instance's methods)."""

    def __init__(self, client: RegisterClient):
        self.counts = {"FC3/4": 0, "FC16": 0, "FC23": 0}
        for meth, key in (("_read", "FC3/4"), ("_write", "FC16"), ("_read_write", "FC23")):
            orig = getattr(client, meth)

            def wrapped(*a, _orig=orig, _key=key):
                self.counts[_key] += 1
                return _orig(*a)
            setattr(client, meth, wrapped)

    def snapshot(self) -> dict:
        return dict(self.counts)


def read_staged_two_requests(ctl: Controller, n: int) -> bytes:
    """The read-back as it was before FC 23: FC 16 (offset) + FC 3 (window) per chunk."""
    out = bytearray()
    chunk = 2 * WINDOW
    for off in range(0, n, chunk):
        ctl.client.write_holding(ctl._h("table_offset"), [off >> 16, off & 0xFFFF])
        m = min(chunk, n - off)
        words = ctl.client.read_holding(ctl._h("table_window"), (m + 1) // 2)
        out += struct.pack(f"<{len(words)}H", *words)[:m]
    return bytes(out)


def flash_once(ctl: Controller, img: bytes, counter: RequestCounter | None = None, *,
               fc23: bool = True, clock=time.perf_counter) -> Phases:
    """Upload, verify and commit ``img``; raises when the controller refuses it
    or the read-back differs."""
    before = counter.snapshot() if counter else {}
    t0 = clock()
    ctl.upload_table(img)
    t1 = clock()
    back = ctl.read_staged(len(img)) if fc23 else read_staged_two_requests(ctl, len(img))
    if back != img:
        bad = next((i for i, (a, b) in enumerate(zip(back, img)) if a != b), min(len(back), len(img)))
        raise RuntimeError(f"read-back differs from the image at byte {bad}")
    if zlib.crc32(back[:-4]) & 0xFFFFFFFF != image_crc(img):
        raise RuntimeError("read-back CRC mismatch")
    t2 = clock()
    result = ctl.commit_table()
    if result != "ok":
        raise RuntimeError(f"the controller refused the table: {result}")
    crc = image_crc(img)
    deadline = clock() + 2.0
    while ctl.status()["active_table_crc"] != crc:
        if clock() > deadline:
            raise RuntimeError("the committed table does not become active")
    t3 = clock()
    req = {}
    if counter:
        after = counter.snapshot()
        req = {k: after[k] - before.get(k, 0) for k in after}
    return Phases(t1 - t0, t2 - t1, t3 - t2, req)


# ---------------------------------------------------------------- the virtual controller
class Sil:
    """sil-stage with TCP on a free port and RTU on a pty, in a temporary directory
    (started by :class:`piezoctl.sil.launch.VirtualController`)."""

    def __init__(self, exe: pathlib.Path, tmp: pathlib.Path):
        self.pty = tmp / "ttyPIEZO"
        self.vc = VirtualController(exe=exe, flash=tmp / "sil.flash", rtu_pty=self.pty).start()
        self.proc = self.vc.proc
        self.port = self.vc.tcp_port

    def stop(self) -> str:
        return self.vc.stop()[1]


# ---------------------------------------------------------------- RTU pacing
class PacedSerial:
    """A pyserial port whose traffic takes the time it would on a real line.

    Half duplex at ``baud`` with ``bits`` bits per character. ``write`` waits
    until the line is free, 3.5 character times (at least 1.75 ms, the fixed
    value above 19200 baud) after the last character received, then for the
    frame's own character times, and only then hands the frame to the port
    (the far end sees its last character when it would arrive). A thread
    reads the port as soon as bytes come and stamps each byte readable one
    character time after the previous one (or after it was written by the far
    end): ``in_waiting`` and ``read`` see only the bytes that have arrived.
    """

    def __init__(self, port, baud: int, bits: int = BITS_PER_CHAR):
        self._port = port
        self.t_char = bits / baud
        self.t_gap = 3.5 * self.t_char if baud <= 19200 else 1.75e-3
        self._fd = port.fileno()
        self._rx: deque = deque()        # (time readable, byte)
        self._last_rx = 0.0               # time the last received character ended
        self._lock = threading.Lock()
        self._stop = False
        self.tx_chars = self.rx_chars = self.tx_frames = 0
        self._thread = threading.Thread(target=self._reader, daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        while not self._stop:
            r, _, _ = select.select([self._fd], [], [], 0.05)
            if not r:
                continue
            try:
                data = os.read(self._fd, 4096)
            except OSError:
                return
            now = time.perf_counter()
            with self._lock:
                t = max(now, self._last_rx)
                for b in data:
                    t += self.t_char
                    self._rx.append((t, b))
                self._last_rx = t
                self.rx_chars += len(data)

    def _arrived(self) -> int:
        now = time.perf_counter()
        with self._lock:
            n = 0
            for t, _ in self._rx:
                if t > now:
                    break
                n += 1
            return n

    @property
    def in_waiting(self) -> int:
        return self._arrived()

    def read(self, size: int = 1) -> bytes:
        deadline = time.perf_counter() + (self._port.timeout or 0.0)
        while True:
            n = self._arrived()
            if n >= size or time.perf_counter() >= deadline:
                break
            with self._lock:
                nxt = self._rx[n][0] if n < len(self._rx) else time.perf_counter() + 0.0005
            time.sleep(max(0.0, min(nxt, deadline) - time.perf_counter()))
        with self._lock:
            k = min(size, n)
            return bytes(self._rx.popleft()[1] for _ in range(k))

    def write(self, data: bytes) -> int:
        with self._lock:
            start = max(time.perf_counter(), self._last_rx + self.t_gap)
        end = start + len(data) * self.t_char
        while (left := end - time.perf_counter()) > 0:
            time.sleep(left)
        n = self._port.write(data)
        self.tx_chars += len(data)
        self.tx_frames += 1
        return n

    def reset_input_buffer(self) -> None:
        with self._lock:
            self._rx.clear()

    def close(self) -> None:
        self._stop = True
        self._thread.join(timeout=1.0)
        self._port.close()

    def __getattr__(self, name):
        return getattr(self._port, name)


def open_paced_rtu(device: str, baud: int):
    """``(client, paced serial)``: the RTU transport with its port paced at ``baud``."""
    client = open_port(f"rtu:{device}:{baud}:N", timeout=1.0)
    paced = PacedSerial(client._client.socket, baud)
    client._client.socket = paced
    return client, paced


# ---------------------------------------------------------------- USB script
class MbapRecorder(RegisterClient):
    """Raw Modbus TCP to sil-stage with the USB transport's request PDUs; keeps
    every (request PDU, answer PDU) in order."""

    def __init__(self, port: int, unit: int = interface.MODBUS_UNIT_ID):
        self.name = f"tcp:127.0.0.1:{port} (recording)"
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.unit = unit
        self.tid = 0
        self.exchanges: list[tuple[bytes, bytes]] = []

    def close(self) -> None:
        self.sock.close()

    def _recv(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            got = self.sock.recv(n - len(buf))
            if not got:
                raise ProtocolError(f"{self.name}: connection closed")
            buf += got
        return buf

    def transact(self, pdu: bytes) -> bytes:
        self.tid = (self.tid + 1) & 0xFFFF
        self.sock.sendall(struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, self.unit) + pdu)
        tid, proto, length, _unit = struct.unpack(">HHHB", self._recv(7))
        if tid != self.tid or proto != 0:
            raise ProtocolError(f"{self.name}: answer to transaction {tid}, asked {self.tid}")
        answer = self._recv(length - 1)
        self.exchanges.append((pdu, answer))
        return answer

    def _read(self, function, address, count):
        return parse_read_response(self.transact(read_request(function, address, count)),
                                   function, count, self.name)

    def _write(self, address, values):
        parse_write_response(self.transact(write_request(address, values)), address, len(values),
                             self.name)

    def _read_write(self, read_address, read_count, write_address, values):
        return parse_read_response(self.transact(read_write_request(read_address, read_count,
                                                                    write_address, values)),
                                   23, read_count, self.name)


def usb_script(exchanges: list[tuple[bytes, bytes]]) -> str:
    """umockdev's usbdevfs script of the exchanges: each request an OUT URB on
    endpoint 0x01 framed with sequence numbers 1, 2, ... (as the USB transport
    numbers them), its answer an IN URB on 0x81 of the transport's read size."""
    lines = [f"@DEV {USB_NODE} (usbdevfs)",
             "# generated by piezoctl.bench.upload: answers computed by the firmware's PDU",
             "# server and register map (sil-stage over Modbus TCP)"]
    for i, (req, rsp) in enumerate(exchanges):
        seq = (i + 1) & 0xFF
        out, inp = frame(seq, req), frame(seq, rsp)
        lines.append(f"USBDEVFS_REAPURBNDELAY 0 3 1 0 0 {len(out)} {len(out)} 0 {out.hex().upper()}")
        lines.append(f" USBDEVFS_REAPURBNDELAY 0 3 129 0 0 {USB_IN_LEN} {len(inp)} 0 {inp.hex().upper()}")
    return "\n".join(lines) + "\n"


def run_sequence(ctl: Controller, images, reps: int, counter=None, fc23: bool = True):
    """``reps`` rounds of flashing every image in turn: {name: [Phases, ...]}."""
    out = {name: [] for name, _ in images}
    for _ in range(reps):
        for name, img in images:
            out[name].append(flash_once(ctl, img, counter, fc23=fc23))
    return out


def _replay_main(args) -> int:
    """Inside umockdev-run: the sequence over pyusb, as JSON on stdout."""
    images = reference_images()
    client = open_port("usb:1209:0001", timeout=1.0)
    counter = RequestCounter(client)
    ctl = Controller(client)
    res = run_sequence(ctl, images, args.reps, counter)
    print(json.dumps({k: [[p.upload, p.verify, p.commit, p.requests] for p in v]
                      for k, v in res.items()}))
    return 0


def bench_usb(sil: Sil, images, reps: int, tmp: pathlib.Path) -> dict:
    """Records the exchanges against ``sil`` and replays them over pyusb under umockdev."""
    rec = MbapRecorder(sil.port)
    ctl = Controller(rec)
    run_sequence(ctl, images, reps)
    rec.close()
    script = tmp / "upload.ioctl"
    script.write_text(usb_script(rec.exchanges))
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "host") + os.pathsep + env.get("PYTHONPATH", "")
    cmd = ["umockdev-run", "--device", str(USB_DEVICE), "--ioctl", f"{USB_NODE}={script}", "--",
           sys.executable, "-m", "piezoctl.bench.upload", "--usb-replay", "--reps", str(reps)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"umockdev replay failed: {proc.stderr.strip()[-2000:]}")
    raw = json.loads(proc.stdout.strip().splitlines()[-1])
    return {"exchanges": len(rec.exchanges),
            "runs": {k: [Phases(u, v, c, r) for u, v, c, r in rows] for k, rows in raw.items()}}


# ---------------------------------------------------------------- report
def median(xs):
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def summarize(runs: list[Phases]) -> dict:
    return {"upload_ms": 1e3 * median([p.upload for p in runs]),
            "verify_ms": 1e3 * median([p.verify for p in runs]),
            "commit_ms": 1e3 * median([p.commit for p in runs]),
            "total_ms": 1e3 * median([p.total for p in runs]),
            "max_ms": 1e3 * max(p.total for p in runs),
            "requests": runs[0].requests}


def rtu_line_ms(chars: int, requests: int, baud: int) -> float:
    """Line occupancy of ``requests`` request/answer pairs carrying ``chars``
    characters both ways: character times + two 3.5-character gaps each."""
    t_char = BITS_PER_CHAR / baud
    gap = 3.5 * t_char if baud <= 19200 else 1.75e-3
    return 1e3 * (chars * t_char + 2 * requests * gap)


def _bench_rtu(sil: Sil, images, reps: int, baud: int, fc23: bool) -> tuple[dict, dict]:
    client, paced = open_paced_rtu(str(sil.pty), baud)
    try:
        counter = RequestCounter(client)
        ctl = Controller(client)
        runs = {}
        line = {}
        for name, img in images:
            runs[name] = []
            chars = []
            for _ in range(reps):
                c0 = paced.tx_chars + paced.rx_chars
                runs[name].append(flash_once(ctl, img, counter, fc23=fc23))
                chars.append(paced.tx_chars + paced.rx_chars - c0)
            nreq = sum(runs[name][0].requests.values())
            line[name] = (chars[0], rtu_line_ms(chars[0], nreq, baud))
        return runs, line
    finally:
        client.close()


def bench(exe: pathlib.Path, *, reps: int = 5, baud: int = 115200, usb: bool = True,
          fc23: bool = True) -> dict:
    images = reference_images()
    out = {"images": {n: len(i) for n, i in images}, "reps": reps, "baud": baud, "fc23": fc23,
           "rows": []}
    with tempfile.TemporaryDirectory(prefix="bench-upload-") as d:
        tmp = pathlib.Path(d)
        sil = Sil(exe, tmp)
        try:
            client = open_port(f"tcp:127.0.0.1:{sil.port}")
            counter = RequestCounter(client)
            ctl = Controller(client)
            for name, img in images:
                flash_once(ctl, img, counter, fc23=fc23)  # warm-up (imports, connection)
            for name, img in images:
                runs = [flash_once(ctl, img, counter, fc23=fc23) for _ in range(reps)]
                out["rows"].append({"transport": "tcp", "image": name, **summarize(runs)})
            client.close()

            runs, line = _bench_rtu(sil, images, max(1, min(reps, 3)), baud, fc23)
            for name, _ in images:
                out["rows"].append({"transport": "rtu", "image": name, **summarize(runs[name]),
                                    "chars": line[name][0], "line_ms": line[name][1]})

            if usb and fc23:
                if shutil.which("umockdev-run") is None:
                    out["usb_skipped"] = "umockdev-run is not installed"
                else:
                    u = bench_usb(sil, images, reps, tmp)
                    out["usb_exchanges"] = u["exchanges"]
                    for name, _ in images:
                        out["rows"].append({"transport": "usb", "image": name,
                                            **summarize(u["runs"][name])})
        finally:
            out["sil_exit"] = sil.stop().strip().splitlines()[-1:]
    for t in ("tcp", "rtu", "usb"):
        rows = [r for r in out["rows"] if r["transport"] == t]
        if rows:
            out.setdefault("sum_ms", {})[t] = sum(r["total_ms"] for r in rows)
    return out


def format_table(res: dict) -> str:
    baud = res["baud"]
    label = {"tcp": "TCP 127.0.0.1",
             "rtu": f"RTU {baud} paced",
             "usb": "USB umockdev"}
    lines = [f"upload + verify + commit of the reference table (KP L=10 + EUPI), "
             f"median of {res['reps']} runs (RTU: {max(1, min(res['reps'], 3))}), "
             f"read-back {'FC 23' if res['fc23'] else 'FC 16 + FC 3'} per chunk",
             f"{'transport':16s} {'image':14s} {'bytes':>5s} {'requests':>20s} {'upload':>8s} "
             f"{'verify':>8s} {'commit':>8s} {'total':>8s} {'max':>8s} {'line':>8s}",
             f"{'':16s} {'':14s} {'':>5s} {'(FC3/4,FC16,FC23)':>20s} {'[ms]':>8s} {'[ms]':>8s} "
             f"{'[ms]':>8s} {'[ms]':>8s} {'[ms]':>8s} {'[ms]':>8s}"]
    for t in ("tcp", "rtu", "usb"):
        rows = [r for r in res["rows"] if r["transport"] == t]
        for r in rows:
            q = r["requests"]
            reqs = f"{sum(q.values())} ({q['FC3/4']},{q['FC16']},{q['FC23']})"
            line = f"{r['line_ms']:8.1f}" if "line_ms" in r else f"{'-':>8s}"
            lines.append(f"{label[t]:16s} {r['image']:14s} {res['images'][r['image']]:5d} {reqs:>20s} "
                         f"{r['upload_ms']:8.1f} {r['verify_ms']:8.1f} {r['commit_ms']:8.1f} "
                         f"{r['total_ms']:8.1f} {r['max_ms']:8.1f} {line}")
        if rows:
            total = res["sum_ms"][t]
            goal = GOALS_MS.get(t)
            verdict = (f"goal < {goal:.0f} ms: {'met' if total < goal else 'MISSED'}"
                       if goal else "no goal (no bus: host stack + umockdev)")
            lines.append(f"{label[t]:16s} {'sum':14s} {sum(res['images'].values()):5d} {'':>20s} "
                         f"{'':8s} {'':8s} {'':8s} {total:8.1f} {'':8s} {'':8s}  {verdict}")
    if "usb_skipped" in res:
        lines.append(f"USB: skipped ({res['usb_skipped']})")
    lines.append(
        f"RTU pacing: the client's port is paced in real time at {baud} baud, {BITS_PER_CHAR} bits a "
        f"character (8 data + start + 2 stop, no parity: a pty refuses parity), 3.5-character gaps "
        f"({1e3 * (3.5 * BITS_PER_CHAR / baud if baud <= 19200 else 1.75e-3):.2f} ms) before each "
        f"request and in the server's framer; 'line' is the computed line occupancy "
        f"(characters both ways + two gaps a request), the floor of the paced time.")
    if "usb_exchanges" in res:
        lines.append(f"USB: {res['usb_exchanges']} exchanges recorded against sil-stage (firmware PDU "
                     f"server + register map) and replayed by umockdev-run, OUT transfers checked "
                     f"byte for byte; the time is the host stack and umockdev, no bus.")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-upload", description=__doc__.splitlines()[0])
    ap.add_argument("--sil", type=pathlib.Path, default=sil_binary(build=False),
                    help="the sil-stage executable")
    ap.add_argument("--reps", type=int, default=5, help="runs per image (RTU: at most 3)")
    ap.add_argument("--baud", type=int, default=115200)
    ap.add_argument("--no-usb", action="store_true", help="skip the umockdev replay")
    ap.add_argument("--two-request-verify", action="store_true",
                    help="read back with FC 16 + FC 3 per chunk (as before FC 23), for comparison")
    ap.add_argument("--json", action="store_true", help="the results as JSON after the table")
    ap.add_argument("--usb-replay", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.usb_replay:
        return _replay_main(args)
    res = bench(args.sil, reps=args.reps, baud=args.baud, usb=not args.no_usb,
                fc23=not args.two_request_verify)
    print(format_table(res))
    if args.json:
        print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
