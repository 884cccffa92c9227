#!/usr/bin/env python3
"""Runs test_uart under QEMU with USART1 on a pair of FIFOs: waits for the
image's "ready\\n", sends the bytes 0..255, then checks that the image
answered with them reversed and "uart ok\\n".

    uart_harness.py QEMU_RUN IMAGE WORKDIR
"""
import os
import pathlib
import select
import subprocess
import sys
import time

READY = b"ready\n"
WANT = READY + bytes(reversed(range(256))) + b"uart ok\n"


def main(qemu_run, image, workdir):
    base = pathlib.Path(workdir) / "uart"
    for end in (".in", ".out"):
        path = pathlib.Path(str(base) + end)
        path.unlink(missing_ok=True)
        os.mkfifo(path)
    # Opened read-write, neither open blocks; QEMU opens them the same way.
    fd_in = os.open(str(base) + ".in", os.O_RDWR)
    fd_out = os.open(str(base) + ".out", os.O_RDWR | os.O_NONBLOCK)
    # Idle time passes in real time here (sleep on): the image waits for
    # QEMU to deliver the bytes.
    proc = subprocess.Popen([qemu_run, "--icount", "shift=0", "--uart-pipe", str(base), image])
    got, sent = b"", False
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd_out], [], [], 0.2)
        if ready:
            got += os.read(fd_out, 4096)
            if not sent and got.startswith(READY):
                os.write(fd_in, bytes(range(256)))  # the UART is up: nothing is lost
                sent = True
        elif proc.poll() is not None:
            break
    rc = proc.wait(timeout=10)
    os.close(fd_in)
    os.close(fd_out)
    if rc != 0:
        print(f"uart_harness: the image failed (exit status {rc})")
        return 1
    if got != WANT:
        first = next((i for i, (a, b) in enumerate(zip(got, WANT)) if a != b), min(len(got), len(WANT)))
        print(f"uart_harness: answer differs at byte {first}: got {len(got)} bytes "
              f"{got[first:first + 8]!r}, want {len(WANT)} bytes {WANT[first:first + 8]!r}")
        return 1
    print(f"uart_harness: 256 bytes in, {len(got)} bytes back as expected")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
