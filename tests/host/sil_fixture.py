"""Start and stop the virtual controller (build/sil/sil_stage) for host tests."""

from __future__ import annotations

import os
import pathlib
import re
import signal
import subprocess
import time

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def sil_binary() -> pathlib.Path:
    build = pathlib.Path(os.environ.get("PIEZOCTL_BUILD", ROOT / "build" / "sil"))
    exe = build / "sil_stage"
    if not exe.exists():
        pytest.skip(f"{exe} not built (run tools/test or cmake --build --preset sil)")
    return exe


class SilStage:
    """A running sil_stage process; ``port`` is its Modbus TCP port."""

    def __init__(self, tmp: pathlib.Path, *args: str, flash: pathlib.Path | None = None):
        self.pty = tmp / "ttyPIEZO"
        self.flash = flash or tmp / "sil.flash"
        cmd = [str(sil_binary()), "--modbus-tcp", "127.0.0.1:0", "--modbus-rtu-pty", str(self.pty),
               "--flash", str(self.flash), *args]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        m = re.search(r"tcp=127\.0\.0\.1:(\d+)", line)
        if not m:
            self.proc.kill()
            raise RuntimeError(f"sil_stage did not start: {line!r} {self.proc.stderr.read()}")
        self.port = int(m.group(1))
        self.spec = f"tcp:127.0.0.1:{self.port}"

    def stop(self) -> tuple[int, str]:
        self.proc.send_signal(signal.SIGTERM)
        out, _err = self.proc.communicate(timeout=10)
        return self.proc.returncode, out


@pytest.fixture
def sil(tmp_path):
    s = SilStage(tmp_path)
    yield s
    if s.proc.poll() is None:
        s.stop()
