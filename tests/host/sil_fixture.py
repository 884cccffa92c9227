"""Start and stop the virtual controller for host tests (through :mod:`piezoctl.sil.launch`)."""

from __future__ import annotations

import pathlib

import pytest

from piezoctl.sil.launch import VirtualController, sil_binary as _built_binary

ROOT = pathlib.Path(__file__).resolve().parents[2]


def sil_binary() -> pathlib.Path:
    """The built sil_stage; the test is skipped when it is not built (tests do not build)."""
    exe = _built_binary(build=False)
    if not exe.exists():
        pytest.skip(f"{exe} not built (run tools/test or cmake --build --preset sil)")
    return exe


class SilStage:
    """A running sil_stage with TCP on a free port and RTU on a pty in ``tmp``.

    ``port`` is its Modbus TCP port (an int), ``spec`` the PORT string
    (``tcp:127.0.0.1:N``), ``pty`` the RTU link, ``flash`` the flash file,
    ``proc`` the process; ``args`` are further sil_stage options.
    """

    def __init__(self, tmp: pathlib.Path, *args: str, flash: pathlib.Path | None = None):
        self.pty = tmp / "ttyPIEZO"
        self.flash = flash or tmp / "sil.flash"
        self.vc = VirtualController(flash=self.flash, rtu_pty=self.pty, args=args, exe=sil_binary()).start()
        self.proc = self.vc.proc
        self.port = self.vc.tcp_port
        self.spec = self.vc.port

    def stop(self) -> tuple[int, str]:
        """SIGTERM; (exit status, the rest of its stdout)."""
        return self.vc.stop()


@pytest.fixture
def sil(tmp_path):
    s = SilStage(tmp_path)
    yield s
    if s.proc.poll() is None:
        s.stop()
