"""Calibrate's targets: ``sil_stage`` (the virtual controller, Modbus TCP) and the PIL image under QEMU
(Modbus RTU on a pseudo-terminal), each started for the duration of a calibration."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import tempfile

from ..errors import CliError

ROOT = pathlib.Path(__file__).resolve().parents[3]


def _build(preset: str, build: pathlib.Path, target: str, what: str, jobs: int) -> None:
    """Configure ``build`` with CMake preset ``preset`` if needed and build ``target``."""
    try:
        if not (build / "CMakeCache.txt").exists():
            subprocess.run(["cmake", "--preset", preset], cwd=ROOT, check=True, capture_output=True)
        subprocess.run(["cmake", "--build", str(build), "--target", target, "-j", str(jobs)],
                       cwd=ROOT, check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        raise CliError(f"cannot build {what} ({target}): {exc}") from None


class SilTarget:
    """A virtual controller running for the duration of a ``with`` block.

    Parameters
    ----------
    stage : str, optional
        Stage parameter file (default: the built-in default stage).
    flash : str, optional
        Flash emulation file (default: a new temporary file, so every
        calibration starts from a controller without a table).
    """

    def __init__(self, stage: str | None = None, flash: str | None = None, seed: int = 1):
        self.stage = stage
        self._tmp = tempfile.TemporaryDirectory(prefix="piezoctl-sil-")
        self.flash = flash or os.path.join(self._tmp.name, "sil.flash")
        self.seed = seed
        self.proc = None
        self.port = None

    def __enter__(self) -> "SilTarget":
        from ..sil.launch import VirtualController, sil_binary  # the one launcher of sil_stage
        self._vc = VirtualController(stage=self.stage, flash=self.flash, seed=self.seed,
                                     exe=sil_binary()).start()
        self.proc, self.port = self._vc.proc, self._vc.port
        return self

    def stats(self) -> str:
        return self._stats

    def __exit__(self, *exc) -> None:
        self._stats = ""
        if self.proc:
            self._vc.stop()
            self._stats = self._vc.stats
        self._tmp.cleanup()


def qemu_image() -> pathlib.Path:
    """The PIL image ``piezoctl-pil`` (an ELF), built with the ``cortex-m4`` preset if missing.

    ``PIEZOCTL_PIL_IMAGE`` names another image; ``PIEZOCTL_CM4_BUILD`` another build directory.
    """
    if os.environ.get("PIEZOCTL_PIL_IMAGE"):
        return pathlib.Path(os.environ["PIEZOCTL_PIL_IMAGE"])
    build = pathlib.Path(os.environ.get("PIEZOCTL_CM4_BUILD", ROOT / "build" / "cortex-m4"))
    _build("cortex-m4", build, "piezoctl-pil", "the PIL image", jobs=1)   # incremental: always up to date
    return build / "firmware" / "targets" / "cortex-m4" / "piezoctl-pil"


# QEMU's netduinoplus2 (STM32F405) with USART1 on a pseudo-terminal.
# -icount shift=0: one instruction is one nanosecond of emulated time, so the
# tick (SysTick) and the work in it are counted in instructions, whatever the
# host's load; sleep=on: while the processor waits (WFI) emulated time passes
# with real time, so the RTU framer's silence (tick stamps, firmware comm.c)
# is never shorter than the silence the host left on the line, and a request
# written in one piece cannot be broken by a gap (docs/target-cortex-m4.md).
QEMU_ARGS = ["-M", "netduinoplus2", "-nodefaults", "-display", "none",
             "-chardev", "pty,id=uart1", "-serial", "chardev:uart1",
             "-semihosting-config", "enable=on,target=native"]
ICOUNT = "shift=0,sleep=on"


class QemuTarget:
    """The PIL image under ``qemu-system-arm`` for the duration of a ``with`` block.

    ``port`` is ``rtu:/dev/pts/N:115200:N`` (a pseudo-terminal has no parity).
    ``image`` is the ELF that runs; ``describe()`` gives the summary's ``target``.
    """

    def __init__(self, image: str | None = None, baud: int = 115200, icount: str = ICOUNT):
        self.image = pathlib.Path(image) if image else None
        self.icount = icount
        self.baud = baud
        self.proc = None
        self.port = None
        self._stats = ""

    def __enter__(self) -> "QemuTarget":
        if self.image is None:
            self.image = qemu_image()
        if not self.image.exists():
            raise CliError(f"no PIL image {self.image}")
        import hashlib
        self._sha256 = hashlib.sha256(self.image.read_bytes()).hexdigest()  # of the bytes QEMU loads
        cmd = ["qemu-system-arm", *QEMU_ARGS, "-icount", self.icount, "-kernel", str(self.image)]
        try:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        except OSError as exc:
            raise CliError(f"cannot start qemu-system-arm: {exc}") from None
        lines = []
        while True:
            line = self.proc.stdout.readline()
            if not line:
                self.proc.wait()
                raise CliError("QEMU did not start: " + " ".join(lines).strip())
            lines.append(line)
            m = re.search(r"redirected to (\S+)", line)
            if m:
                break
        self.port = f"rtu:{m.group(1)}:{self.baud}:N"
        return self

    def describe(self) -> dict:
        return {"kind": "qemu", "transport": "rtu", "image": str(self.image.resolve()),
                "image_sha256": self._sha256}

    def stats(self) -> str:
        return self._stats

    def __exit__(self, *exc) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                out, _ = self.proc.communicate(timeout=10)
                self._stats = (out or "").strip()
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
