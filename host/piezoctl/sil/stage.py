"""ctypes binding of the C stage model (``libpiezo_stage.so``).

The stage model is C code shared with the SIL build (``piezo_stage``); the
host loads the same objects as a shared library, so a simulation here gives
bit for bit the samples the SIL firmware sees. The JSON parameter file is
read by the C code: one parser, one set of error messages.

The library is looked up in this order:

1. the path in the environment variable ``PIEZOCTL_STAGE_LIB``;
2. ``build/sil/libpiezo_stage.so`` of this checkout (``cmake --preset sil &&
   cmake --build --preset sil``).

Examples
--------
>>> import numpy as np
>>> from piezoctl.sil import simulate_stage, default_stage_path
>>> t = np.arange(1000) / 10000.0
>>> y = simulate_stage(default_stage_path(), t, np.full(t.size, 75.0), seed=1)  # doctest: +SKIP
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np

from ..errors import CliError

__all__ = [
    "StageLibraryError",
    "StageParamsError",
    "StageInputError",
    "default_stage_path",
    "find_library",
    "simulate_stage",
    "stage_info",
]

ENV_VAR = "PIEZOCTL_STAGE_LIB"
LIB_NAME = "libpiezo_stage.so"
ABI_VERSION = 1
REPO_ROOT = Path(__file__).resolve().parents[3]
STAGES_DIR = REPO_ROOT / "firmware" / "targets" / "sil" / "stages"
BUILD_HINT = "build it with: cmake --preset sil && cmake --build --preset sil (or tools/test)"

_STAGE_ERRORS = {-1: "bad argument", -2: "parameter out of range", -3: "file error", -4: "JSON error"}


class StageLibraryError(CliError, RuntimeError):
    """The stage model's shared library is missing or does not match."""


class StageParamsError(CliError, ValueError):
    """The stage parameter file is missing or wrong (the C reader's message)."""


class StageInputError(CliError, ValueError):
    """The drive or its time column cannot be simulated (one line saying what is wrong)."""


def default_stage_path(name: str = "default") -> Path:
    """Path of a shipped stage parameter file: ``default`` or ``two_axis``."""
    return STAGES_DIR / f"{name}.json"


def find_library() -> Path:
    """Path of ``libpiezo_stage.so``; raises :class:`StageLibraryError` if absent."""
    env = os.environ.get(ENV_VAR)
    if env:
        p = Path(env)
        if not p.is_file():
            raise StageLibraryError(f"{ENV_VAR}={env}: no such file; unset it or point it at {LIB_NAME}")
        return p
    p = REPO_ROOT / "build" / "sil" / LIB_NAME
    if p.is_file():
        return p
    raise StageLibraryError(f"the stage model library {LIB_NAME} is not built (looked for {p}); {BUILD_HINT}")


_loaded: dict[Path, ctypes.CDLL] = {}


def _library() -> ctypes.CDLL:
    path = find_library().resolve()
    lib = _loaded.get(path)
    if lib is not None:
        return lib
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise StageLibraryError(f"cannot load {path}: {exc}; {BUILD_HINT}") from exc
    try:
        version = lib.stage_abi_version()
    except AttributeError as exc:
        raise StageLibraryError(f"{path} is not the stage model library; {BUILD_HINT}") from exc
    if version != ABI_VERSION:
        raise StageLibraryError(f"{path}: ABI version {version}, this host needs {ABI_VERSION}; rebuild it")
    dp = ctypes.POINTER(ctypes.c_double)
    lib.stage_simulate_file.argtypes = [ctypes.c_char_p, ctypes.c_uint64, ctypes.c_double, ctypes.c_size_t,
                                        dp, dp, dp, dp, ctypes.c_char_p, ctypes.c_size_t]
    lib.stage_simulate_file.restype = ctypes.c_int
    lib.stage_file_info.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_int), dp, ctypes.c_char_p,
                                    ctypes.c_size_t]
    lib.stage_file_info.restype = ctypes.c_int
    _loaded[path] = lib
    return lib


def _raise_for(rc: int, err: ctypes.Array, path) -> None:
    if rc != 0:
        msg = err.value.decode("utf-8", "replace") or _STAGE_ERRORS.get(rc, f"error {rc}")
        raise StageParamsError(msg if str(path) in msg else f"{path}: {msg}")


def stage_info(params_path) -> tuple[int, float]:
    """Reads a stage parameter file (in C) and returns (axes, sample rate [Hz])."""
    lib = _library()
    err = ctypes.create_string_buffer(512)
    n = ctypes.c_int(0)
    fs = ctypes.c_double(0.0)
    rc = lib.stage_file_info(os.fsencode(params_path), ctypes.byref(n), ctypes.byref(fs), err, len(err))
    _raise_for(rc, err, params_path)
    return n.value, fs.value


def _as_input(name: str, x, n: int) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != 1 or a.size != n:
        raise StageInputError(f"{name}: expected {n} samples (one per t), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise StageInputError(f"{name}: contains NaN or infinite values")
    return a


def simulate_stage(params_path, t, u, u2=None, seed: int = 1, sample_rate_hz: float | None = None):
    """Simulates the stage of a parameter file for the drive ``u`` [V].

    Parameters
    ----------
    params_path : str or Path
        Stage parameter file (JSON, docs/stage-model.md), read by the C code.
    t : array_like, shape (n,)
        Sample times [s], uniformly spaced to 1e-6 of a step (a recording's
        printed times are not: ``piezoctl simulate`` puts them on the uniform
        grid of :func:`piezoctl.ident.frf.sample_rate` first). Their rate is the simulation's;
        when it agrees with the file's ``sample_rate_hz`` to 1e-6, the file's
        exact value is used (so the samples equal the SIL build's).
    u : array_like, shape (n,)
        Drive of axis 1: the amplifier's output voltage [V] (converted to DAC
        codes through the amplifier's nominal gain and offset).
    u2 : array_like, shape (n,), optional
        Drive of axis 2 for a two-axis stage (0 V when omitted).
    seed : int
        Seed of the sensor noise; the same seed gives the same samples.
    sample_rate_hz : float, optional
        Overrides the rate taken from ``t``.

    Returns
    -------
    y : ndarray, shape (n,)
        Measured displacement [um] (through the sensor and ADC) of axis 1;
        ``(y, y2)`` for a two-axis stage.

    Raises
    ------
    StageParamsError
        The file is missing or wrong (message with file, line and key).
    StageInputError
        ``t``, ``u`` or ``u2`` cannot be simulated (not uniform, wrong length,
        not finite, ``u2`` for a one-axis stage).
    StageLibraryError
        ``libpiezo_stage.so`` is not built.
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    if t.ndim != 1:
        raise StageInputError("t: expected a 1-D array of sample times")
    n = t.size
    u = _as_input("u", u, n)
    axes, fs_file = stage_info(params_path)
    if u2 is not None:
        if axes != 2:
            raise StageInputError(f"{params_path}: a one-axis stage; u2 is for two-axis stages")
        u2 = _as_input("u2", u2, n)
    fs = 0.0
    if sample_rate_hz is not None:
        fs = float(sample_rate_hz)
    elif n >= 2:
        dt = np.diff(t)
        if not np.all(dt > 0) or np.ptp(dt) > 1e-6 * float(np.mean(dt)) + 1e-12:
            # the model has one rate; a printed time column (a few digits) is not exact:
            # the caller decides the grid (piezoctl simulate: piezoctl.ident.frf.sample_rate)
            raise StageInputError(
                f"t: sample times are not uniformly spaced to 1e-6 of a step (steps {dt.min():.9g}..{dt.max():.9g} s); "
                f"the stage model runs at one rate: pass sample_rate_hz or times on a uniform grid")
        fs_t = (n - 1) / (t[-1] - t[0])
        fs = 0.0 if abs(fs_t / fs_file - 1.0) < 1e-6 else fs_t
    if fs < 0 or not np.isfinite(fs):
        raise StageInputError(f"sample rate {fs}: must be > 0")
    y = np.zeros(n)
    y2 = np.zeros(n) if axes == 2 else None
    dp = ctypes.POINTER(ctypes.c_double)

    def ptr(a):
        return a.ctypes.data_as(dp) if a is not None else None

    err = ctypes.create_string_buffer(512)
    rc = _library().stage_simulate_file(os.fsencode(params_path), int(seed) & (2**64 - 1), fs, n,
                                        ptr(u), ptr(u2), ptr(y), ptr(y2), err, len(err))
    _raise_for(rc, err, params_path)
    return (y, y2) if axes == 2 else y
