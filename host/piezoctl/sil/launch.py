"""Start the virtual controller: the one launcher of ``sil_stage``.

``sil_stage`` (``firmware/targets/sil/sil_stage_main.c``) is the firmware's
controller against the C stage model, paced at 10 kHz, serving Modbus TCP
(and RTU on a pseudo-terminal). Everything that needs one running goes
through this module: ``tools/sil-stage`` (:func:`main`), the host tests
(``tests/host/sil_fixture.py``), ``piezoctl calibrate --target sil``
(:class:`piezoctl.calibrate.target.SilTarget`) and the upload benchmark
(:mod:`piezoctl.bench.upload`).

Where the build lives: ``$PIEZOCTL_BUILD``, else ``build/sil`` of this
checkout (:func:`build_dir`); :func:`sil_binary` builds ``sil_stage`` there
(configuring the ``sil`` CMake preset first when needed).

Start-up handshake: ``sil_stage`` prints one line ``sil-stage: ready
tcp=HOST:PORT axes=N rtu=LINK`` on stdout once it listens; with
``--modbus-tcp 127.0.0.1:0`` the system picks a free port, read from that
line. On SIGTERM it stops and prints its statistics (the last line,
``sil-stage: stats ...``).

Examples
--------
>>> from piezoctl.sil.launch import VirtualController
>>> with VirtualController() as vc:          # doctest: +SKIP
...     print(vc.port)                       # tcp:127.0.0.1:PORT for piezoctl.device.connect
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from ..errors import CliError

__all__ = ["ROOT", "BUILD_ENV", "SilLaunchError", "build_dir", "sil_binary", "VirtualController", "main"]

ROOT = Path(__file__).resolve().parents[3]
BUILD_ENV = "PIEZOCTL_BUILD"
_READY = re.compile(r"tcp=([\d.]+):(\d+)")


class SilLaunchError(CliError):
    """The virtual controller could not be built or did not start (exit 2)."""


def build_dir() -> Path:
    """The SIL build directory: ``$PIEZOCTL_BUILD``, else ``build/sil`` of this checkout."""
    return Path(os.environ.get(BUILD_ENV) or ROOT / "build" / "sil")


def sil_binary(*, build: bool = True, jobs: int = 2) -> Path:
    """Path of ``sil_stage`` in :func:`build_dir`.

    Parameters
    ----------
    build : bool
        Bring it up to date first (``cmake --preset sil`` when the directory
        is not configured, then ``cmake --build DIR --target sil_stage``).
        With ``False`` the path is returned whether or not it exists.
    jobs : int
        Parallel build jobs.

    Raises
    ------
    SilLaunchError
        The configure or build step failed (its last output lines included).
    """
    bdir = build_dir()
    exe = bdir / "sil_stage"
    if not build:
        return exe
    steps = []
    if not (bdir / "CMakeCache.txt").exists():
        steps.append(["cmake", "--preset", "sil", "-B", str(bdir)])
    steps.append(["cmake", "--build", str(bdir), "--target", "sil_stage", "-j", str(jobs)])
    for cmd in steps:
        try:
            r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        except OSError as exc:
            raise SilLaunchError(f"cannot build the virtual controller: {exc}") from None
        if r.returncode:
            tail = " | ".join((r.stdout + r.stderr).strip().splitlines()[-3:])
            raise SilLaunchError(f"cannot build the virtual controller ({' '.join(cmd)}): {tail}")
    return exe


class VirtualController:
    """``sil_stage`` as a child process, for the duration of a ``with`` block.

    Parameters
    ----------
    stage : str or Path, optional
        Stage parameter file (``--stage``; default: the built-in default stage).
    flash : str or Path, optional
        Flash emulation file (``--flash``). Default: a file in a temporary
        directory removed at :meth:`stop`, so the controller starts without
        a table.
    seed : int, optional
        Noise seed of the stage model (``--seed``).
    rtu_pty : str or Path, optional
        Also serve Modbus RTU on a pseudo-terminal linked at this path
        (``--modbus-rtu-pty``).
    args : sequence of str
        Further ``sil_stage`` options (e.g. ``["--unlock-key", "0123ABCD"]``).
    exe : str or Path, optional
        The executable (default: :func:`sil_binary`, built if needed).
    host : str
        Address to listen on; the port is chosen by the system.

    Attributes
    ----------
    port : str
        ``tcp:HOST:PORT``, a PORT for :func:`piezoctl.device.connect`.
    tcp_port : int
        The TCP port alone.
    proc : subprocess.Popen
        The process (stdout: its handshake and statistics lines).
    """

    def __init__(self, *, stage=None, flash=None, seed: int | None = None, rtu_pty=None,
                 args=(), exe=None, host: str = "127.0.0.1"):
        self.stage = None if stage is None else str(stage)
        self._tmp = None
        if flash is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="piezoctl-sil-")
            flash = os.path.join(self._tmp.name, "sil.flash")
        self.flash = str(flash)
        self.seed = seed
        self.rtu_pty = None if rtu_pty is None else str(rtu_pty)
        self.args = [str(a) for a in args]
        self.exe = None if exe is None else str(exe)
        self.host = host
        self.proc: subprocess.Popen | None = None
        self.port: str | None = None
        self.tcp_port: int | None = None
        self.stats = ""

    def command(self) -> list[str]:
        """The ``sil_stage`` command line."""
        cmd = [self.exe or str(sil_binary()), "--modbus-tcp", f"{self.host}:0", "--flash", self.flash]
        if self.rtu_pty:
            cmd += ["--modbus-rtu-pty", self.rtu_pty]
        if self.stage:
            cmd += ["--stage", self.stage]
        if self.seed is not None:
            cmd += ["--seed", str(self.seed)]
        return cmd + self.args

    def start(self) -> "VirtualController":
        """Start it and wait for its ready line; raises :class:`SilLaunchError` if it does not come."""
        cmd = self.command()
        # stderr to a file: nothing reads it while the controller runs, so a pipe could fill up
        self._err = tempfile.TemporaryFile(mode="w+")
        try:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self._err, text=True)
        except OSError as exc:
            raise SilLaunchError(f"cannot start the virtual controller {cmd[0]}: {exc}") from None
        line = self.proc.stdout.readline()
        m = _READY.search(line)
        if not m:
            self.proc.kill()
            self.proc.wait()
            self._err.seek(0)
            why = (self._err.read().strip() or line.strip() or f"exit status {self.proc.returncode}")
            self._cleanup()
            raise SilLaunchError(f"the virtual controller did not start: {why}")
        self.tcp_port = int(m.group(2))
        self.port = f"tcp:{m.group(1)}:{self.tcp_port}"
        return self

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout: float = 10.0, sig: int = signal.SIGTERM) -> tuple[int, str]:
        """Send ``sig`` (SIGTERM; SIGKILL to simulate a crash), wait (kill after
        ``timeout`` s); returns (exit status, the rest of its stdout).

        :attr:`stats` keeps the last stdout line (``sil-stage: stats ...``).
        Safe to call twice.
        """
        if self.proc is None:
            return 0, ""
        out = ""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            out, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
        except ValueError:  # already communicated
            out = ""
        out = out or ""
        if out.strip():
            self.stats = out.strip().splitlines()[-1]
        self._cleanup()
        return self.proc.returncode, out

    def stderr_text(self) -> str:
        """What it wrote on stderr so far."""
        try:
            self._err.seek(0)
            return self._err.read()
        except (AttributeError, ValueError):
            return ""

    def _cleanup(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self) -> "VirtualController":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    """``tools/sil-stage ARGS...``: bring ``sil_stage`` up to date and run it in this process."""
    argv = sys.argv[1:] if argv is None else argv
    try:
        exe = sil_binary()
    except SilLaunchError as exc:
        print(f"sil-stage: {exc}", file=sys.stderr)
        return 2
    sys.stdout.flush()
    os.execv(str(exe), [str(exe), *argv])
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main())
