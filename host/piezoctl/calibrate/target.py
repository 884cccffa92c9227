"""The SIL target: start ``sil_stage`` (the virtual controller) for calibrate."""

from __future__ import annotations

import os
import pathlib
import re
import signal
import subprocess
import tempfile

from ..errors import CliError

ROOT = pathlib.Path(__file__).resolve().parents[3]


def sil_binary() -> pathlib.Path:
    """The sil_stage executable, built with the ``sil`` preset if missing."""
    build = pathlib.Path(os.environ.get("PIEZOCTL_BUILD", ROOT / "build" / "sil"))
    exe = build / "sil_stage"
    if not exe.exists():
        try:
            if not (build / "CMakeCache.txt").exists():
                subprocess.run(["cmake", "--preset", "sil"], cwd=ROOT, check=True, capture_output=True)
            subprocess.run(["cmake", "--build", str(build), "--target", "sil_stage", "-j", "2"],
                           cwd=ROOT, check=True, capture_output=True)
        except (OSError, subprocess.CalledProcessError) as exc:
            raise CliError(f"cannot build the virtual controller (sil_stage): {exc}") from None
    return exe


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
        cmd = [str(sil_binary()), "--modbus-tcp", "127.0.0.1:0", "--flash", self.flash, "--seed", str(self.seed)]
        if self.stage:
            cmd += ["--stage", self.stage]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        m = re.search(r"tcp=([\d.]+):(\d+)", line)
        if not m:
            err = self.proc.stderr.read()
            self.proc.kill()
            raise CliError(f"the virtual controller did not start: {(err or line).strip()}")
        self.port = f"tcp:{m.group(1)}:{m.group(2)}"
        return self

    def stats(self) -> str:
        return self._stats

    def __exit__(self, *exc) -> None:
        self._stats = ""
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                out, _ = self.proc.communicate(timeout=10)
                self._stats = out.strip().splitlines()[-1] if out.strip() else ""
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self._tmp.cleanup()
