"""Signal processing shared by the models, identification and the diagnosis.

Discrete filters that start at the equilibrium of their first input sample (a
recording starts from rest or from a settled state, never from zero), a
zero-order-hold mode, a slew limiter and the low-passed drive rate. Units:
seconds for ``dt`` and time constants, hertz for frequencies; signals keep the
unit of their input.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools

import numpy as np
from scipy import signal

__all__ = ["filt", "lowpass", "lowpass_tau", "mode_filter", "slew_limit", "drive_rate", "RATE_CUTOFF_HZ",
           "turning_points", "stroke_half_excursion", "blas_threads"]

RATE_CUTOFF_HZ = 50.0
_SLEW_SCALAR = 32   # slew_limit: ramp steps taken one by one before the rest is taken as an array


_ZI_CACHE: dict = {}
_ZI_CACHE_MAX = 1024   # entries (each a few floats)


def _lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``signal.lfilter_zi(b, a)`` (read-only), kept per exact coefficients: the diagnosis filters with the same
    few dynamics thousands of times (5875 calls on s0-017, 3.4 s under the profiler, for a few dozen filters)."""
    key = (b.tobytes(), a.tobytes())
    zi = _ZI_CACHE.get(key)
    if zi is None:
        zi = signal.lfilter_zi(b, a)
        zi.setflags(write=False)
        if len(_ZI_CACHE) >= _ZI_CACHE_MAX:
            _ZI_CACHE.clear()
        _ZI_CACHE[key] = zi
    return zi


def filt(b, a, x) -> np.ndarray:
    """``lfilter(b, a, x)`` starting at the equilibrium of ``x[0]`` (static gain ``sum b / sum a``)."""
    b = np.asarray(b, float)
    a = np.asarray(a, float)
    x = np.asarray(x, float)
    if b.size == 1 and a.size == 1:
        return x * (b[0] / a[0])
    zi = _lfilter_zi(b, a)
    if x.ndim == 1:
        return signal.lfilter(b, a, x, zi=zi * x[0])[0]
    return signal.lfilter(b, a, x, axis=0, zi=zi[:, None] * x[0][None, :])[0]


def flush_subnormal(x: np.ndarray) -> np.ndarray:
    """Set the subnormal entries of the float array ``x`` (``0 < |x| < 2.2e-308``) to 0, in place; returns ``x``.

    A filter's response to a column that is zero outside a short range (a play's hat function) decays into
    the subnormal range and, for a slow pole, stays there (``a * x`` rounds back to ``x``): products with a
    subnormal operand take the processor's slow path, and a Gram matrix of such columns took 10 to 50 times
    longer (docs/diagnose-rounds/round-25.md, "Round 25: speed"). With the other factors of the data's scale
    (|x| < 1e6) such a product is below 1e-301, and it changes no sum that also holds a term of the data's scale
    (checked bit for bit on the base fit: tests/host/test_diagnose_speed_round25.py)."""
    x[np.abs(x) < np.finfo(x.dtype).tiny] = 0.0
    return x


def lowpass(x, hz: float, dt: float) -> np.ndarray:
    """First-order low-pass (pole ``hz`` [Hz], exact for a held input), from equilibrium."""
    c = 1.0 - np.exp(-2.0 * np.pi * float(hz) * dt)
    return filt([c], [1.0, c - 1.0], x)


def lowpass_tau(x, tau_s: float, dt: float) -> np.ndarray:
    """First-order low-pass with time constant ``tau_s`` [s], from equilibrium."""
    c = 1.0 - np.exp(-dt / float(tau_s))
    return filt([c], [1.0, c - 1.0], x)


def mode_filter(freq_hz: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (zero-order hold) unit-gain mode ``w^2 / (s^2 + 2 z w s + w^2)``: (b, a) (new arrays per call)."""
    bd, ad = _mode_filter(float(freq_hz), float(damping), float(dt))
    return bd.copy(), ad.copy()


@functools.lru_cache(maxsize=4096)
def _mode_filter(freq_hz: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    # round 22: the resonance term asks the same (f, zeta, dt) per recording, fold and round; scipy's
    # cont2discrete (a matrix exponential) took 2.6 s of held-out s125-023's 75 s for 1176 calls
    w = 2.0 * np.pi * freq_hz
    bd, ad, _ = signal.cont2discrete(([w * w], [1.0, 2.0 * damping * w, w * w]), dt, method="zoh")
    return np.ravel(bd), np.ravel(ad)


def slew_limit(u, max_step: float) -> np.ndarray:
    """Limit the change of ``u`` per sample to ``max_step`` (the amplifier's slew rate times dt).

    The recursion ``out[k] = out[k-1] + clip(u[k] - out[k-1], -max_step, max_step)``, evaluated by stretches:
    samples where ``u`` moves by at most ``max_step`` are copied; where the limit acts, the output is a ramp,
    computed in chunks as a cumulative sum of steps (``np.cumsum`` adds in order, so every ramp value is the
    same float the sample-by-sample recursion gives) and cut where ``u`` comes back within one step of it.
    """
    u = np.asarray(u, dtype=float)
    out = u.copy()
    if u.size < 2 or not np.isfinite(max_step):
        return out
    viol = np.flatnonzero(np.abs(np.diff(u)) > max_step) + 1
    if viol.size == 0:
        return out
    n = u.size
    i = int(viol[0])
    prev = float(out[i - 1])
    scalar = _SLEW_SCALAR       # steps left before a ramp is taken as an array
    chunk = 16
    while i < n:
        d = float(u[i]) - prev
        up = d > max_step
        if not (up or d < -max_step):
            # caught up: the output follows u until the next sample where u itself jumps by more than a step
            out[i] = u[i]
            k = int(np.searchsorted(viol, i, side="right"))
            if k >= viol.size:
                break
            i = int(viol[k])
            prev = float(out[i - 1])
            scalar, chunk = _SLEW_SCALAR, 16
            continue
        step = max_step if up else -max_step
        if scalar > 0:          # a short ramp (a chirp's fast half-cycle): scalar steps cost less than array calls
            prev += step
            out[i] = prev
            i += 1
            scalar -= 1
            continue
        # a long ramp from prev: candidate values prev + step, prev + 2 step, ... (summed in order)
        m = min(chunk, n - i)
        ramp = np.full(m + 1, step)
        ramp[0] = prev
        np.cumsum(ramp, out=ramp)
        # the ramp holds at sample i + q while u[i + q] is beyond a step from the value before it (ramp[q])
        dq = u[i:i + m] - ramp[:m]
        go = dq > max_step if up else dq < -max_step
        stop = m if go.all() else int(np.argmin(go))
        out[i:i + stop] = ramp[1:stop + 1]
        prev = float(ramp[stop])
        i += stop
        if stop == m:
            chunk = min(4 * chunk, 1 << 16)
        else:
            scalar, chunk = _SLEW_SCALAR, 16
    return out


def drive_rate(v, dt: float, cutoff_hz: float = RATE_CUTOFF_HZ) -> np.ndarray:
    """Magnitude of the drive rate [FS/s], low-passed at ``cutoff_hz`` [Hz]."""
    r = np.abs(np.gradient(np.asarray(v, float), dt)) if len(v) > 1 else np.zeros(len(v))
    return lowpass(r, cutoff_hz, dt)


def turning_points(v) -> np.ndarray:
    """Where a signal reverses: the indices ``i`` of ``diff(v)`` whose step is the first in a new direction
    (steps of zero are skipped), so ``v[i]`` is the extreme it turned at.

    Parameters
    ----------
    v : array_like
        The signal (any unit), e.g. the drive [V] or a play's output.

    Returns
    -------
    ndarray of int
        The indices, increasing; empty when the signal moves in one direction or not at all.
    """
    d = np.sign(np.diff(np.asarray(v, float)))
    nz = np.flatnonzero(d)
    if nz.size < 2:
        return np.zeros(0, np.intp)
    dn = d[nz]
    return nz[np.flatnonzero(dn[1:] != dn[:-1]) + 1]


def stroke_half_excursion(v, deadband: float) -> np.ndarray:
    """Half the excursion of the stroke each sample lies on: the signal's travel from the reversal before it to
    the reversal after it, halved. A reversal counts once the signal has come back more than ``deadband`` from its
    extreme (so the noise's wiggles do not split a stroke).

    A play of threshold r reverses on a stroke only when the stroke's half excursion exceeds r: on a periodic drive
    of amplitude A it is A.

    Parameters
    ----------
    v : array_like
        The signal (any unit), e.g. the normalized drive [FS].
    deadband : float
        The return that confirms a reversal (the unit of ``v``), >= 0.

    Returns
    -------
    ndarray
        Per sample, the half excursion (the unit of ``v``); zeros for fewer than two samples.
    """
    v = np.asarray(v, float)
    n = v.size
    out = np.zeros(n)
    if n < 2:
        return out
    pts = np.concatenate([[0], turning_points(v), [n - 1]])
    keep, trend, ext = [0], 0, 0
    for p in pts[1:]:
        x = v[p]
        if trend == 0:                       # no direction yet: the first move beyond the deadband sets it
            if abs(x - v[0]) > deadband:
                trend, ext = (1 if x > v[0] else -1), p
        elif (x - v[ext]) * trend >= 0:      # further the same way: the extreme moves on
            ext = p
        elif abs(x - v[ext]) > deadband:     # came back beyond the deadband: the extreme was a reversal
            keep.append(ext)
            trend, ext = -trend, p
    keep.append(ext if trend else n - 1)
    if keep[-1] != n - 1:
        keep.append(n - 1)
    keep = np.unique(np.asarray(keep, np.intp))
    for a, b in zip(keep[:-1], keep[1:]):
        out[a:b + 1] = 0.5 * abs(v[b] - v[a])
    return out


# (set, get) entry points of the OpenBLAS builds numpy and scipy load (their wheels rename the symbols)
_BLAS_THREAD_SYMBOLS = (("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
                        ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
                        ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
                        ("openblas_set_num_threads", "openblas_get_num_threads"))


def _openblas_controls() -> list:
    """(set, get) functions of every OpenBLAS library loaded in this process (numpy's and scipy's are two
    separate libraries, each with its own threads); empty when none is found (another BLAS: nothing to do)."""
    try:
        with open("/proc/self/maps") as f:
            paths = sorted({ln.split()[-1] for ln in f if "openblas" in ln.lower() and ".so" in ln})
    except OSError:
        return []
    out = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for set_name, get_name in _BLAS_THREAD_SYMBOLS:
            if hasattr(lib, set_name) and hasattr(lib, get_name):
                st, gt = getattr(lib, set_name), getattr(lib, get_name)
                st.argtypes, st.restype, gt.argtypes, gt.restype = [ctypes.c_int], None, [], ctypes.c_int
                out.append((st, gt))
                break
    return out


@contextlib.contextmanager
def blas_threads(n: int = 1):
    """Run the block with the loaded OpenBLAS libraries limited to ``n`` threads [count], restored after.

    Why: the diagnosis' BLAS calls are small (Gram matrices of a few hundred thousand rows and at most a few
    hundred columns, matrix-vector products); on two cores with the other one busy, OpenBLAS's second thread
    waits for a core and its partner spins: case s103-008 (foreign, scale 0.5) took 29.2 and 29.7 s of CPU
    with the default two threads and 12.9 and 11.6 s with one, under the shared load (docs/diagnose-speed.md).
    Results differ by round-off only (another blocking of the same sums)."""
    ctl = _openblas_controls()
    old = [gt() for _, gt in ctl]
    for st, _ in ctl:
        st(int(n))
    try:
        yield
    finally:
        for (st, _), k in zip(ctl, old):
            st(int(k))
