"""Rate-independent hysteresis operators of the ``refined`` model kind (float64).

Three operator types, selected by ``hp["type"]`` of a ``refined`` model's
``hysteresis`` block (docs/model-file.md); all act on the normalized drive
``v = (u - u_mid) / u_half`` and return micrometres:

``plane`` (the diagnosis base since round 5)
    A discretized Preisach plane written through play operators. The relay
    with switching thresholds ``s - r`` and ``s + r`` is up exactly when the
    play of threshold ``r`` (started in the same state) has an output above
    ``s``, so a Preisach model whose density is piecewise constant in ``s``
    and discrete in ``r`` is ``H(v) = sum_j F_j(P_rj(v))``, each ``F_j`` a
    piecewise-linear function (knots ``knots[j]``, values ``values[j]``) of
    one play's output. ``r_0 = 0`` is the reversible (anhysteretic) part.
    No parametric family: any rate-independent hysteresis with wiping-out
    and congruent minor loops is reached as the grid refines. Outside its
    knots each ``F_j`` continues as a straight line (the calibration said
    nothing beyond its range).
``pi``
    Classical Prandtl-Ishlinskii plays with a clamped cubic (model files of
    rounds 1-4).
``bouc_wen``
    A Bouc-Wen element with a clamped cubic (model files of rounds 1-4).

Operator states depend only on the drive and the shape parameters, so they
are kept in a small LRU cache keyed on both: the diagnosis reruns one
operator on one drive many times with different weights.
"""

from __future__ import annotations

import bisect
import collections
import hashlib
import json
import math
import zlib

import numpy as np

from .play import play_outputs

__all__ = ["bouc_wen_h", "play_states", "hat_basis", "interp_linear_ext", "plane_parts", "hysteresis_parts",
           "hysteresis_output", "hysteresis_output_of", "clear_output_cache",
           "poly_clamped", "hysteresis_features", "plane_feature_blocks", "add_to_features", "hysteresis_channels",
           "scale_channels", "hysteresis_groups", "scale_groups", "initial_state_span", "plays_varying",
           "plane_width_change"]

_STATE_CACHE: "collections.OrderedDict" = collections.OrderedDict()
_STATE_CACHE_MAX_SAMPLES = 20_000_000   # about 160 MB of float64


def _cached_state(kind: str, params: tuple, v: np.ndarray, compute) -> np.ndarray:
    """The hysteresis state for drive ``v`` from a small LRU cache keyed on the parameters and the drive.

    The diagnosis runs the same operator on the same drive many times (per fold and round, for every setting of
    a drive-side term, on the calibration for each refit of the dynamics); the state depends only on the drive
    and the operator's shape parameters, not on the weights that change between those runs. The key holds the
    drive's CRC-32 (0.8 ms per 3.5 MB, a sixth of a cryptographic hash's time); an entry keeps a copy of its
    drive and a hit is confirmed by comparing the drives exactly, so a CRC collision costs a recomputation,
    never a wrong state. Returns a read-only array (callers must not modify it)."""
    v = np.ascontiguousarray(v, dtype=float)
    key = (kind, params, v.size, zlib.crc32(v.view(np.uint8)))
    hit = _STATE_CACHE.get(key)
    if hit is not None and np.array_equal(hit[0], v):
        _STATE_CACHE.move_to_end(key)
        return hit[1]
    out = compute(v)
    out.setflags(write=False)
    v_copy = v.copy()
    v_copy.setflags(write=False)
    _STATE_CACHE[key] = (v_copy, out)
    _STATE_CACHE.move_to_end(key)
    total = sum(a.size + b.size for a, b in _STATE_CACHE.values())
    while total > _STATE_CACHE_MAX_SAMPLES and len(_STATE_CACHE) > 1:
        a, b = _STATE_CACHE.popitem(last=False)[1]
        total -= a.size + b.size
    return out


def _peek_state(kind: str, params: tuple, v: np.ndarray):
    """The cached state for drive ``v`` (contiguous float64) or None; computes nothing, stores nothing."""
    hit = _STATE_CACHE.get((kind, params, v.size, zlib.crc32(v.view(np.uint8))))
    if hit is not None and np.array_equal(hit[0], v):
        return hit[1]
    return None


def bouc_wen_h(v, beta: float, gamma: float, v_rest: float = 0.0, n: float = 1.0, h0: float = 0.0) -> np.ndarray:
    """Hysteretic state of a Bouc-Wen element of exponent ``n`` (see :func:`_bouc_wen_h`; ``n != 1``:
    :func:`_bouc_wen_h_n`) starting at state ``h0`` at ``v_rest``, cached: read-only result."""
    if float(n) == 1.0:
        return _cached_state("bw", (float(beta), float(gamma), float(v_rest), float(h0)), v,
                             lambda x: _bouc_wen_h(x, float(beta), float(gamma), float(v_rest), float(h0)))
    return _cached_state("bwn", (float(beta), float(gamma), float(v_rest), float(n), float(h0)), v,
                         lambda x: _bouc_wen_h_n(x, float(beta), float(gamma), float(v_rest), float(n), float(h0)))


BW_TABLE_POINTS = 16001  # points of the tabulated run solution of a Bouc-Wen element with n != 1


def _monotone_runs(v, v_rest: float):
    """(dv, starts, ends): the drive's steps from ``v_rest`` [V] and its monotone runs, run k being the steps
    ``starts[k]:ends[k]``. A run starts at the first nonzero step and at every change of direction; zero steps belong
    to the run before them. ``starts`` is empty when the drive never moves."""
    dv = np.diff(np.concatenate([[v_rest], np.asarray(v, float)]))
    nz = np.flatnonzero(dv != 0.0)
    if nz.size == 0:
        return dv, nz, nz
    sgn = np.sign(dv[nz])
    starts = nz[np.concatenate([[0], np.flatnonzero(sgn[1:] != sgn[:-1]) + 1])]
    return dv, starts, np.append(starts[1:], dv.size)


def _bouc_wen_table(beta: float, gamma: float, n: float):
    """(h, L): the ascending run solution of ``dh/dL = 1 - |h|^n (beta sign(h) + gamma)`` from the descending
    limit ``-h_u`` to the ascending one ``h_u = (beta + gamma)^(-1/n)``, as the path length L [normalized drive]
    needed to reach each h. L(h) is the integral of 1 / g(h); it is evaluated by the trapezoid rule in
    ``q = log(h_u - h)`` (uniform q: the grid crowds where 1 / g diverges logarithmically at h_u), down to
    ``h_u - h = 1e-12 h_u`` (dq = 0.002: the table's interpolation error is about 1e-5 of h_u)."""
    hu = (beta + gamma) ** (-1.0 / n)
    q = np.linspace(np.log(2.0 * hu), np.log(1e-12 * hu), BW_TABLE_POINTS)
    h = hu - np.exp(q)
    g = 1.0 - np.abs(h) ** n * (beta * np.sign(h) + gamma)
    f = np.exp(q) / np.maximum(g, 1e-300)          # dL/dq up to the sign: |dh/dq| / g
    L = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.abs(np.diff(q)))])
    return h, L


def _bouc_wen_h_n(v, beta: float, gamma: float, v_rest: float = 0.0, n: float = 2.0,
                  h_start: float = 0.0) -> np.ndarray:
    """Hysteretic state h of a Bouc-Wen element of exponent ``n`` (alpha = 1) along the drive path v.

    ``dh = dv - |h|^n (beta sign(h dv) + gamma) |dv|`` (``beta > |gamma|``), starting at h = ``h_start`` at
    ``v_rest`` (clipped inside the limits +-h_u); n = 1
    is :func:`_bouc_wen_h`. Rate independent and autonomous within a monotone run: an ascending run moves h
    along the tabulated solution (:func:`_bouc_wen_table`) by the path length travelled, a descending run does
    the same on -h (the law is odd). The Python loop runs over turning points (one scalar lookup each); the
    samples are filled by one interpolation."""
    hgrid, Lgrid = _bouc_wen_table(beta, gamma, n)
    dv, starts, ends = _monotone_runs(v, v_rest)
    h0 = float(np.clip(h_start, hgrid[0], hgrid[-1]))
    out = np.full(dv.size, h0)
    if starts.size == 0:
        return out
    path = np.concatenate([[0.0], np.cumsum(np.abs(dv))])
    sd = np.sign(dv[starts])
    # per run: the table position at its start (L0) from the state the previous run ended in
    hl, Ll = hgrid.tolist(), Lgrid.tolist()

    def lookup(x, xs, ys):     # scalar linear interpolation, clamped (np.interp costs more per scalar call)
        i = min(max(bisect.bisect_right(xs, x) - 1, 0), len(xs) - 2)
        f = min(max((x - xs[i]) / (xs[i + 1] - xs[i]), 0.0), 1.0) if xs[i + 1] > xs[i] else 0.0
        return ys[i] + f * (ys[i + 1] - ys[i])

    L0 = np.empty(starts.size)
    runlen = (path[ends] - path[starts]).tolist()
    for k, (s, dl) in enumerate(zip(sd.tolist(), runlen)):
        L0[k] = lookup(s * h0, hl, Ll)
        h0 = s * lookup(L0[k] + dl, Ll, hl)
    run = np.repeat(np.arange(starts.size), ends - starts)
    first = starts[0]
    Ls = L0[run] + path[first + 1:] - path[starts[run]]
    out[first:] = sd[run] * np.interp(Ls, Lgrid, hgrid)
    return out


def _bouc_wen_h(v, beta: float, gamma: float, v_rest: float = 0.0, h_start: float = 0.0) -> np.ndarray:
    """Hysteretic state h of a Bouc-Wen element with alpha = 1 along the drive path v.

    ``dh = dv - beta |dv| h - gamma dv |h|`` (``beta > |gamma|``), starting at h = ``h_start`` at
    ``v_rest`` (clipped inside the limits +-1 / (beta + gamma)). Rate independent: within a monotone run of
    the drive (direction s) h is a
    closed-form function of the path length L travelled in the run,
    ``h = heq + (h0 - heq) exp(-k L)``, ``k = beta + s sign(h) gamma``, ``heq = s / k``;
    when h starts against the direction it reaches zero after
    ``l0 = log(1 - h0 / heq) / k`` and continues with ``k = beta + gamma``. Evaluated
    exactly at every sample, one run at a time (a drive step of any size is exact).
    """
    dv, starts, ends = _monotone_runs(v, v_rest)
    kp, km = beta + gamma, beta - gamma
    h0 = float(np.clip(h_start, -(1.0 - 1e-9) / kp, (1.0 - 1e-9) / kp))
    out = np.full(dv.size, h0)
    if starts.size == 0:
        return out
    path = np.cumsum(np.abs(dv))
    hs = []
    sds = np.sign(dv[starts]).tolist()
    p0s = np.concatenate([[0.0], path])[starts].tolist()
    for a, b, sd, p0 in zip(starts.tolist(), ends.tolist(), sds, p0s):
        if b - a <= 12:  # short runs (a chirp's high end): scalar arithmetic is cheaper than array calls
            for L in (path[a:b] - p0).tolist():
                if h0 == 0.0 or (h0 > 0) == (sd > 0):
                    h = sd / kp + (h0 - sd / kp) * math.exp(-kp * L)
                else:
                    heq = sd / km
                    l0 = math.log(1.0 - h0 / heq) / km
                    h = (heq + (h0 - heq) * math.exp(-km * L)) if L < l0 else sd / kp * (1.0 - math.exp(-kp * (L - l0)))
                hs.append(h)
            out[a:b] = hs
            h0 = hs[-1]
            hs.clear()
            continue
        L = path[a:b] - p0
        if h0 == 0.0 or (h0 > 0) == (sd > 0):
            heq = sd / kp
            seg = heq + (h0 - heq) * np.exp(-kp * L)
        else:
            heq = sd / km
            l0 = float(np.log(1.0 - h0 / heq)) / km
            heq2 = sd / kp
            seg = np.where(L < l0, heq + (h0 - heq) * np.exp(-km * np.minimum(L, l0)),
                           heq2 * (1.0 - np.exp(-kp * np.maximum(L - l0, 0.0))))
        out[a:b] = seg
        h0 = float(seg[-1])
    return out


def play_states(v, r, v_rest: float = 0.0) -> np.ndarray:
    """Outputs (T, n) of classical plays of thresholds ``r`` [normalized drive] started relaxed at ``v_rest``,
    cached: read-only result."""
    r = np.asarray(r, float)
    v = np.asarray(v, float)
    if v.size == 0:
        return np.zeros((0, r.size))
    # column-major: each play's output is contiguous, as the per-play kernels (interpolation, hat basis) read it
    return _cached_state("play", (tuple(r.tolist()), float(v_rest)), v,
                         lambda x: play_outputs(x, r, y0=np.full(r.size, float(v_rest)), order="F"))


def _segments(x, knots):
    """Segment index i (0..K-2) and fraction f of each x between knots i and i+1; f < 0 or > 1 beyond the ends
    (linear continuation of the end segments)."""
    k = np.asarray(knots, float)
    h = (k[-1] - k[0]) / (k.size - 1)
    if h > 0 and np.allclose(np.diff(k), h, rtol=1e-9, atol=0.0):   # evenly spaced (the base's knots): no search
        q = (np.asarray(x, float) - k[0]) / h
        i = np.clip(np.floor(q), 0, k.size - 2).astype(np.intp)
        return i, q - i
    i = np.clip(np.searchsorted(k, x, side="right") - 1, 0, k.size - 2)
    f = (x - k[i]) / (k[i + 1] - k[i])
    return i, f


def hat_basis(x, knots) -> np.ndarray:
    """Piecewise-linear (hat) basis (n, K) of x on increasing ``knots``, continued linearly beyond the end knots.

    Column k is the piecewise-linear function that is 1 at knot k and 0 at the others; the columns sum to 1
    everywhere (also beyond the ends)."""
    x = np.asarray(x, float)
    K = len(knots)
    i, f = _segments(x, knots)
    out = np.zeros((x.size, K))
    rows = np.arange(x.size)
    out[rows, i] = 1.0 - f
    out[rows, i + 1] += f
    return out


def _strictly_increasing(knots) -> bool:
    k = np.asarray(knots, float)
    return k.size >= 2 and bool(np.all(k[1:] > k[:-1]))


def interp_linear_ext(x, knots, values) -> np.ndarray:
    """The piecewise-linear function through (knots, values), continued linearly beyond the end knots.

    ``np.interp`` inside the knots (one C pass, its search seeded by the previous sample's segment), the end
    segments' straight lines only on the samples beyond them; equal to the segment formula
    ``values[i] (1 - f) + values[i+1] f`` to round-off (tests/host/test_kernels_speed_equivalence.py)."""
    x = np.ascontiguousarray(x, dtype=float)
    kn = np.asarray(knots, float)
    vals = np.asarray(values, float)
    if not _strictly_increasing(kn):    # repeated knots: the segment formula (and its division by zero)
        i, f = _segments(x, kn)
        return vals[i] * (1.0 - f) + vals[i + 1] * f
    out = np.interp(x, kn, vals)
    if x.size:
        lo, hi = kn[0], kn[-1]
        if x.min() < lo:
            m = np.flatnonzero(x < lo)
            s0 = (vals[1] - vals[0]) / (kn[1] - kn[0])
            out[m] = vals[0] + s0 * (x[m] - lo)
        if x.max() > hi:
            m = np.flatnonzero(x > hi)
            s1 = (vals[-1] - vals[-2]) / (kn[-1] - kn[-2])
            out[m] = vals[-1] + s1 * (x[m] - hi)
    return out


def _sum_of_pl(knots_list, values_list):
    """(knots, values) of the sum of piecewise-linear functions, each continued linearly beyond its ends: a
    piecewise-linear function on the union of the knots, continued linearly beyond the union's ends."""
    kn = np.unique(np.concatenate([np.asarray(k, float) for k in knots_list]))
    vals = np.zeros(kn.size)
    for k, v in zip(knots_list, values_list):
        vals += interp_linear_ext(kn, k, v)
    return kn, vals


# samples per block of plane_parts' fused play + interpolation (16 plays: 8 MB). Round 13: 65,536 instead of 16,384,
# 8 to 10 % less time on s0-017's drives (8 and 16 plays; fewer calls and runs cut at block ends), the same floats
_PLANE_BLOCK = 65536


def plane_parts(hp: dict, v, hysteretic: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """(H[v] without offset, hysteretic part) [um] of a ``plane`` operator; the hysteretic part is
    ``sum_{j>=1} F_j(P_rj(v)) - F_j(v)``: the branch-dependent deviation from the operator's central curve.

    ``sum_{j>=1} F_j(v)`` is one piecewise-linear function of v (on the union of the knots), evaluated once.
    The play states come from the state cache when they are there; otherwise they are computed block by
    block, each block's plays interpolated while they are in cache, and not stored: the diagnosis calls this
    on a new drive (a drive-side term's setting) almost every time, and a (T, n) state per call would only
    evict the states that are reused. Blocks start from the previous block's last outputs, so the plays are
    the same recursion, bit for bit.

    ``hysteretic=False``: H only (the hysteretic part is None), the same floats of H; what
    :func:`hysteresis_output` asks for (the per-play sums of the hysteretic part and its central curve over
    the whole drive were about a fifth of each call there)."""
    v = np.ascontiguousarray(v, dtype=float)
    r = np.asarray(hp["r"], float)
    v_rest = float(hp.get("v_rest", 0.0))
    knots = [np.asarray(k, float) for k in hp["knots"]]
    values = [np.asarray(x, float) for x in hp["values"]]
    h = np.zeros(v.size)
    hyst = np.zeros(v.size) if hysteretic else None

    def add(P, hb, yb):
        for j, (kn, vals) in enumerate(zip(knots, values)):
            fj = interp_linear_ext(P[:, j], kn, vals)
            hb += fj
            if yb is not None and r[j] > 0:
                yb += fj

    P = _peek_state("play", (tuple(r.tolist()), v_rest), v) if v.size else None
    if P is not None:
        add(P, h, hyst)
    elif v.size:
        f = np.full(r.size, v_rest)
        for k0 in range(0, v.size, _PLANE_BLOCK):
            P = play_outputs(v[k0:k0 + _PLANE_BLOCK], r, y0=f, order="F")
            f = P[-1].copy()
            add(P, h[k0:k0 + _PLANE_BLOCK], None if hyst is None else hyst[k0:k0 + _PLANE_BLOCK])
    central = [j for j in range(r.size) if r[j] > 0] if hysteretic else []
    if central:
        if all(_strictly_increasing(knots[j]) for j in central):
            hyst -= interp_linear_ext(v, *_sum_of_pl([knots[j] for j in central], [values[j] for j in central]))
        else:
            for j in central:
                hyst -= interp_linear_ext(v, knots[j], values[j])
    bw = hp.get("bw")
    if bw:
        hb = float(bw["c_h"]) * bouc_wen_h(v, float(bw["beta"]), float(bw["gamma"]), v_rest, float(bw.get("n", 1.0)),
                                           float(bw.get("h0", 0.0)))
        h += hb
        if hyst is not None:
            hyst += hb
    return h, hyst


def poly_clamped(v, poly, v_lo, v_hi) -> np.ndarray:
    """Cubic of v inside ``[v_lo, v_hi]`` (the calibrated range), continued outside it as a straight
    line with the cubic's *mean* slope over the range (its secant): a cubic fitted on a narrow range
    has an unreliable slope at its ends, the mean gain is what the calibration determined."""
    c1, c2, c3 = (list(poly) + [0.0, 0.0, 0.0])[:3]
    vc = np.clip(v, v_lo, v_hi)
    p = ((c3 * vc + c2) * vc + c1) * vc
    if v_hi > v_lo:
        slope = (c1 * (v_hi - v_lo) + c2 * (v_hi ** 2 - v_lo ** 2) + c3 * (v_hi ** 3 - v_lo ** 3)) / (v_hi - v_lo)
    else:
        slope = c1
    return p + slope * (v - vc)


def hysteresis_parts(hp: dict, v) -> tuple[np.ndarray, np.ndarray]:
    """(H[v] without offset, hysteretic part) [um] for normalized drive v.

    ``type`` ``"plane"``: see :func:`plane_parts`; ``"pi"`` (default): plays, hysteretic part
    ``sum w_i (P_i(v) - v)``; ``"bouc_wen"``: ``c_h h(v; beta, gamma) + poly(v)``, hysteretic part ``c_h h``.
    """
    v = np.asarray(v, float)
    kind = hp.get("type", "pi")
    if kind == "plane":
        return plane_parts(hp, v)
    if kind == "bouc_wen":
        hh = float(hp["c_h"]) * bouc_wen_h(v, float(hp["beta"]), float(hp["gamma"]), float(hp.get("v_rest", 0.0)))
        return hh + poly_clamped(v, hp["poly"], hp["v_lo"], hp["v_hi"]), hh
    r = np.asarray(hp["r"], float)
    w = np.asarray(hp["w"], float)
    P = play_states(v, r, float(hp.get("v_rest", 0.0)))
    hyst = P @ w - float(w.sum()) * v
    out = float(w.sum()) * v + hyst + poly_clamped(v, hp["poly"], hp["v_lo"], hp["v_hi"])
    return out, hyst


_OUTPUT_CACHE: "collections.OrderedDict" = collections.OrderedDict()
_OUTPUT_CACHE_MAX_SAMPLES = 48_000_000   # H outputs kept: about 380 MB of float64


def _op_text(hp: dict) -> str:
    """The operator without its offset as JSON text (floats written exactly): what H depends on besides the drive."""
    return json.dumps({k: x for k, x in hp.items() if k != "offset"}, sort_keys=True,
                      default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o))


def _output_key(hp: dict, v: np.ndarray, op: str | None = None) -> tuple:
    """What H[v] depends on: the operator without its offset (``_op_text``) and the drive (its size and SHA-256
    digest: a collision has probability 2^-256; about 5 ms per 9 MB)."""
    return _op_text(hp) if op is None else op, v.size, hashlib.sha256(v.view(np.uint8)).digest()


def hysteresis_output(hp: dict, v) -> np.ndarray:
    """H[v] without offset [um] (the first output of :func:`hysteresis_parts`, the same floats), cached: a
    read-only result.

    The diagnosis runs the current hysteresis on a changed drive for every setting of a drive-side term
    (bandwidth, slew limit, saturation) on every recording, and again for each fold's model, each selection
    round and the all-data model; those models share the base's operator unless an accepted term refitted it
    (an intercept only moves the offset, which is not part of the key). On case s0-017 that was 1708 runs of
    the plane. At most ``_OUTPUT_CACHE_MAX_SAMPLES`` samples are kept (only H: the hysteretic part is not asked
    for there). When full, a new output of the operator the oldest entry belongs to is not stored (the settings
    recur in the same order every round: evicting the oldest would evict each one just before it is asked for
    again), while an output of another operator (a term refitted the hysteresis) evicts the oldest entries.
    :func:`clear_output_cache` empties it."""
    return _output(hp, np.ascontiguousarray(v, dtype=float))[0]


def _output(hp: dict, v: np.ndarray, op: str | None = None) -> tuple[np.ndarray, tuple]:
    """(H[v], its cache key): :func:`hysteresis_output`'s work, ``v`` contiguous float64."""
    key = _output_key(hp, v, op)
    hit = _OUTPUT_CACHE.get(key)
    if hit is not None:
        _OUTPUT_CACHE.move_to_end(key)
        return hit, key
    h = plane_parts(hp, v, hysteretic=False)[0] if hp.get("type", "pi") == "plane" else hysteresis_parts(hp, v)[0]
    if not h.flags.owndata:     # never keep a view of a cached state
        h = h.copy()
    h.setflags(write=False)
    total = sum(x.size for x in _OUTPUT_CACHE.values())
    while _OUTPUT_CACHE and total + v.size > _OUTPUT_CACHE_MAX_SAMPLES:
        if next(iter(_OUTPUT_CACHE))[0] == key[0]:
            return h, key       # full of this operator's outputs: keep them
        total -= _OUTPUT_CACHE.popitem(last=False)[1].size
    if total + v.size <= _OUTPUT_CACHE_MAX_SAMPLES:
        _OUTPUT_CACHE[key] = h
    return h, key


# (operator text, tag, id(anchor)) -> (anchor, output key or None): which drive a tag stands for (round 13)
_OUTPUT_ALIAS: dict = {}
_OUTPUT_ALIAS_MAX = 20_000   # entries (each a few references); emptied when reached


def hysteresis_output_of(hp: dict, tag: tuple, anchor, make_v):
    """``hysteresis_output(hp, make_v())`` without computing ``make_v()`` again when ``tag`` and ``anchor`` were
    seen with this operator and the output is still cached; None when ``make_v()`` returns None (the caller's
    "unchanged drive").

    ``tag`` (hashable) and ``anchor`` (an object kept and compared by identity, e.g. the unchanged drive's array)
    must determine ``make_v()`` exactly: the diagnosis' drive-side settings (``ident.terms``: the term, its
    setting, the normalization and the recording's drive) recur per fold model, round and the all-data model,
    and each recurrence recomputed the changed drive (a slew limiter, a low-pass, a clip) and its SHA-256 key
    only to find H cached. Emptied with the output cache (:func:`clear_output_cache`)."""
    op = _op_text(hp)
    akey = (op, tag, id(anchor))   # the entry keeps its anchor alive: its id is not reused while it is there
    a = _OUTPUT_ALIAS.get(akey)
    if a is not None and a[0] is anchor:
        if a[1] is None:
            return None
        hit = _OUTPUT_CACHE.get(a[1])
        if hit is not None:
            _OUTPUT_CACHE.move_to_end(a[1])
            return hit
    v = make_v()
    if len(_OUTPUT_ALIAS) >= _OUTPUT_ALIAS_MAX:
        _OUTPUT_ALIAS.clear()
    if v is None:
        _OUTPUT_ALIAS[akey] = (anchor, None)
        return None
    h, key = _output(hp, np.ascontiguousarray(v, dtype=float), op)
    _OUTPUT_ALIAS[akey] = (anchor, key)
    return h


def clear_output_cache() -> None:
    """Empty the cache of :func:`hysteresis_output` (the diagnosis does when its selection is done), the tags
    of :func:`hysteresis_output_of` and the cache of :func:`plane_width_change_cached`."""
    _OUTPUT_CACHE.clear()
    _OUTPUT_ALIAS.clear()
    _WIDTH_CACHE.clear()


_WIDTH_CACHE: dict = {}
_WIDTH_CACHE_MAX_SAMPLES = 16_000_000   # widened-play changes kept: at most about 128 MB of float64


def plane_width_change_cached(hp: dict, v, width, shift=None) -> np.ndarray:
    """:func:`plane_width_change` (the same floats, a read-only array), kept for a recurring operator, drive and
    width.

    The diagnosis' rate term widens the base's plays on every recording for each of its settings, in each fold's
    context and each selection round; the folds' and rounds' models share the base's operator unless an accepted
    term refitted it, so the same change was computed again (round 23: held-out null s125-023, 453 calls of which
    227 repeated an earlier call's operator, drive and width exactly, 4.1 of its 70 s CPU). Key: the operator
    without its offset (``plane_width_change`` does not read it) as exact JSON text, the sizes and the SHA-256
    digests of the drive and of the width. At most ``_WIDTH_CACHE_MAX_SAMPLES`` samples are kept; when full a new
    change is computed and not stored. Emptied by :func:`clear_output_cache` (the end of the selection)."""
    v = np.ascontiguousarray(v, dtype=float)
    w = np.ascontiguousarray(np.asarray(width, float).reshape(-1))
    key = _output_key(hp, v) + (w.size, hashlib.sha256(w.view(np.uint8)).digest())
    if shift is not None:   # round 24: the narrowing's shift is part of the key
        sh = np.ascontiguousarray(np.asarray(shift, float).reshape(-1))
        key = key + (sh.size, hashlib.sha256(sh.view(np.uint8)).digest())
    hit = _WIDTH_CACHE.get(key)
    if hit is not None:
        return hit
    out = plane_width_change(hp, v, w, shift)
    out.setflags(write=False)
    if sum(x.size for x in _WIDTH_CACHE.values()) + out.size <= _WIDTH_CACHE_MAX_SAMPLES:
        _WIDTH_CACHE[key] = out
    return out


def hysteresis_features(hp: dict, v) -> tuple[np.ndarray, np.ndarray]:
    """(F, theta): columns F (n, k) of the operator's linear part for normalized drive v and the coefficients
    theta that reproduce H (without offset) as ``F @ theta``. A refit of theta on new data is a refit of the
    operator's own flexibility (the diagnosis' nested tests use it as their nuisance).

    ``plane``: each play's hat basis (first hat left out, its value is 0); ``pi``: plays, v, v^2, v^3 (clamped);
    ``bouc_wen``: the state h, v, v^2, v^3 (clamped)."""
    v = np.asarray(v, float)
    kind = hp.get("type", "pi")
    if kind == "plane":
        F = np.hstack(list(plane_feature_blocks(hp, v)))
        th = np.concatenate([np.asarray(vals[1:], float) - float(vals[0]) for vals in hp["values"]])
        if hp.get("bw"):
            th = np.append(th, float(hp["bw"]["c_h"]))
        return F, th
    vc = np.clip(v, float(hp.get("v_lo", -1.0)), float(hp.get("v_hi", 1.0)))
    if kind == "bouc_wen":
        H = bouc_wen_h(v, float(hp["beta"]), float(hp["gamma"]), float(hp.get("v_rest", 0.0)))[:, None]
        th = [float(hp["c_h"])]
    else:
        H = play_states(v, np.asarray(hp["r"], float), float(hp.get("v_rest", 0.0)))
        th = list(map(float, hp["w"]))
    return np.column_stack([H, vc, vc ** 2, vc ** 3]), np.array(th + list(hp["poly"])[:3], float)


def plane_feature_blocks(hp: dict, v):
    """The columns of :func:`hysteresis_features` for a ``plane`` operator, one block at a time: each play's hat
    basis (n, K - 1), then the Bouc-Wen column (n, 1) when there is one. A caller that filters or decimates
    each block at once never holds the whole (n, k) matrix at full rate (k up to about a hundred)."""
    v = np.asarray(v, float)
    P = play_states(v, np.asarray(hp["r"], float), float(hp.get("v_rest", 0.0)))
    for j, kn in enumerate(hp["knots"]):
        yield hat_basis(P[:, j], kn)[:, 1:]
    bw = hp.get("bw")
    if bw:
        yield bouc_wen_h(v, float(bw["beta"]), float(bw["gamma"]), float(hp.get("v_rest", 0.0)),
                         float(bw.get("n", 1.0)), float(bw.get("h0", 0.0)))[:, None]


def add_to_features(hp: dict, dtheta) -> dict:
    """A copy of ``hp`` whose linear part (see :func:`hysteresis_features`) has ``dtheta`` added."""
    import copy
    out = copy.deepcopy(hp)
    d = np.asarray(dtheta, float)
    kind = hp.get("type", "pi")
    if kind == "plane":
        c = 0
        for j, vals in enumerate(out["values"]):
            k = len(vals) - 1
            out["values"][j] = [float(vals[0])] + [float(x) + float(y) for x, y in zip(vals[1:], d[c:c + k])]
            c += k
        if out.get("bw"):
            out["bw"]["c_h"] = float(out["bw"]["c_h"]) + float(d[c])
        return out
    n = d.size - 3
    if kind == "bouc_wen":
        out["c_h"] = float(out["c_h"]) + float(d[0])
    else:
        out["w"] = [float(w) + float(q) for w, q in zip(out["w"], d[:n])]
    out["poly"] = [float(c) + float(q) for c, q in zip(out["poly"], d[n:n + 3])]
    return out


def hysteresis_channels(hp: dict, v) -> np.ndarray:
    """The operator's output split into channels (n, m) that sum to H (without offset) [um]: per play of a
    ``plane`` its ``F_j(P_rj(v))`` (and the Bouc-Wen column's contribution); for ``pi`` and ``bouc_wen`` the
    hysteretic part and the rest. Free gains on these channels are a low-dimensional refit of the operator's
    own flexibility: loop width per threshold, the reversible curve's gain."""
    v = np.asarray(v, float)
    if hp.get("type", "pi") != "plane":
        h, hyst = hysteresis_parts(hp, v)
        return np.column_stack([hyst, h - hyst])
    P = play_states(v, np.asarray(hp["r"], float), float(hp.get("v_rest", 0.0)))
    cols = [interp_linear_ext(P[:, j], kn, vals) for j, (kn, vals) in enumerate(zip(hp["knots"], hp["values"]))]
    bw = hp.get("bw")
    if bw:
        cols.append(float(bw["c_h"]) * bouc_wen_h(v, float(bw["beta"]), float(bw["gamma"]),
                                                  float(hp.get("v_rest", 0.0)), float(bw.get("n", 1.0)),
                                                  float(bw.get("h0", 0.0))))
    return np.column_stack(cols)


def scale_channels(hp: dict, gains) -> dict:
    """A copy of ``hp`` whose channels (see :func:`hysteresis_channels`) are multiplied by ``1 + gains``."""
    import copy
    out = copy.deepcopy(hp)
    g = 1.0 + np.asarray(gains, float)
    if hp.get("type", "pi") != "plane":
        # channels: the hysteretic part, the rest (plays' reversible slope and the cubic)
        if hp.get("type") == "bouc_wen":
            out["c_h"] = float(out["c_h"]) * float(g[0])
        else:
            w = np.asarray(out["w"], float)
            # PI: hysteretic part sum w (P - v), rest sum(w) v + cubic: both scale with w only through the split
            out["w"] = (w * float(g[0])).tolist()
            out["poly"] = [float(c) * float(g[1]) + (float(g[1]) - float(g[0])) * (float(w.sum()) if i == 0 else 0.0)
                           for i, c in enumerate(out["poly"])]
            return out
        out["poly"] = [float(c) * float(g[1]) for c in out["poly"]]
        return out
    n = len(out["values"])
    for j in range(n):
        out["values"][j] = [float(x) * float(g[j]) for x in out["values"][j]]
    if out.get("bw"):
        out["bw"]["c_h"] = float(out["bw"]["c_h"]) * float(g[n])
    return out


def hysteresis_groups(hp: dict, v) -> np.ndarray:
    """The operator's output in at most three groups (n, m) that sum to H (without offset) [um]: the reversible
    curve, the hysteretic part (every play of threshold > 0 together), the Bouc-Wen column; for ``pi`` and
    ``bouc_wen`` the same two channels as :func:`hysteresis_channels`. Free gains on these are the diagnosis'
    refit of the base's own flexibility: the reversible gain and the loop width. A gain per play threshold
    (up to 16) is so flexible that it also stands in for a session offset over the drive range a recording
    covers."""
    if hp.get("type", "pi") != "plane":
        return hysteresis_channels(hp, v)
    # accumulated group by group (not the channels' (T, n) matrix summed by columns: a third of the time)
    v = np.asarray(v, float)
    r = np.asarray(hp["r"], float)
    P = play_states(v, r, float(hp.get("v_rest", 0.0)))
    rev = np.zeros(v.size) if np.any(r == 0.0) else None
    hys = np.zeros(v.size) if np.any(r != 0.0) else None
    for j, (kn, vals) in enumerate(zip(hp["knots"], hp["values"])):
        fj = interp_linear_ext(P[:, j], kn, vals)
        if r[j] == 0.0:
            rev += fj
        else:
            hys += fj
    cols = [c for c in (rev, hys) if c is not None]
    if hp.get("bw"):
        cols.append(bouc_wen_column(hp, v))
    return np.column_stack(cols)


def bouc_wen_column(hp: dict, v) -> np.ndarray:
    """A ``plane`` operator's Bouc-Wen column ``c_h h(v)`` [um] (zeros without one or for other types)."""
    v = np.asarray(v, float)
    bw = hp.get("bw") if hp.get("type", "pi") == "plane" else None
    if not bw:
        return np.zeros(v.size)
    return float(bw["c_h"]) * bouc_wen_h(v, float(bw["beta"]), float(bw["gamma"]), float(hp.get("v_rest", 0.0)),
                                         float(bw.get("n", 1.0)), float(bw.get("h0", 0.0)))


def scale_groups(hp: dict, gains) -> dict:
    """A copy of ``hp`` whose groups (see :func:`hysteresis_groups`) are multiplied by ``1 + gains``."""
    if hp.get("type", "pi") != "plane":
        return scale_channels(hp, gains)
    n = len(hp["values"])
    r0 = [j for j, r in enumerate(hp["r"]) if float(r) == 0.0]
    rest = [j for j in range(n) if j not in r0]
    g = list(np.asarray(gains, float))
    per = np.zeros(n + (1 if hp.get("bw") else 0))
    k = 0
    for group in (r0, rest):
        if group:
            per[group] = g[k]
            k += 1
    if hp.get("bw"):
        per[n] = g[k]
    return scale_channels(hp, per)


def plays_varying(v, R, y0) -> np.ndarray:
    """Outputs (T, n) of plays whose thresholds vary with time, ``R`` (T, n) [normalized drive], from states
    ``y0`` (n,).

    Taken one monotone run of the drive at a time: on a rising run each play follows its lower edge
    ``v - R`` upward (the running maximum from the run's first state) and is held below its upper edge ``v + R``;
    on a falling run the mirror image. A play therefore keeps the threshold it had when it last moved until the
    drive pushes it again: the memory holds the loop width of the last motion. With constant thresholds this is
    the classical play, bit for bit (``play_outputs``)."""
    v = np.ascontiguousarray(v, dtype=float)
    R = np.asarray(R, float)
    T, n = R.shape
    out = np.empty((T, n))
    if T == 0:
        return out
    d = np.sign(np.diff(v))
    nz = np.flatnonzero(d != 0)
    starts = [0]
    if nz.size:
        s_nz = d[nz]
        starts += (nz[np.flatnonzero(s_nz[1:] != s_nz[:-1]) + 1] + 1).tolist()
    starts.append(T)
    y = np.asarray(y0, float).reshape(n).copy()
    for a, b in zip(starts[:-1], starts[1:]):
        lo = v[a:b, None] - R[a:b]
        hi = v[a:b, None] + R[a:b]
        if v[b - 1] >= v[a]:
            q = np.maximum(np.maximum.accumulate(lo, axis=0), np.minimum(hi[0], y)[None, :])
            np.minimum(q, hi, out=q)
        else:
            q = np.minimum(np.minimum.accumulate(hi, axis=0), np.maximum(lo[0], y)[None, :])
            np.maximum(q, lo, out=q)
        out[a:b] = q
        y = q[-1]
    return out


def plane_width_change(hp: dict, v, width, shift=None) -> np.ndarray:
    """Change [um] of a ``plane`` operator's output when every play's threshold is multiplied by ``width`` (T,)
    [1] at each sample: ``sum_{r_j > 0} F_j(P_{r_j width}(v)) - F_j(P_{r_j}(v))`` (:func:`plays_varying`). The
    reversible curve (threshold 0) and a Bouc-Wen column are unchanged. Zero for other operator types.

    ``shift`` (T,) [normalized drive], optional (round 24): the thresholds are ``max(r_j width - shift, 0)``, every
    play's threshold moved by the same amount whatever its size (a loop that narrows with ``shift > 0``)."""
    v = np.ascontiguousarray(v, dtype=float)
    out = np.zeros(v.size)
    if hp.get("type", "pi") != "plane" or v.size == 0:
        return out
    r = np.asarray(hp["r"], float)
    hyst = np.flatnonzero(r > 0)
    if hyst.size == 0:
        return out
    v_rest = float(hp.get("v_rest", 0.0))
    P0 = play_states(v, r, v_rest)
    w = np.asarray(width, float).reshape(-1)
    R = w[:, None] * r[None, hyst]
    if shift is not None:
        R = np.maximum(R - np.asarray(shift, float).reshape(-1)[:, None], 0.0)
    P1 = plays_varying(v, R, np.full(hyst.size, v_rest))
    for i, j in enumerate(hyst):
        kn, vals = hp["knots"][j], hp["values"][j]
        out += interp_linear_ext(P1[:, i], kn, vals) - interp_linear_ext(P0[:, j], kn, vals)
    return out


def initial_state_span(hp: dict, v, v_lo: float, v_hi: float) -> np.ndarray:
    """H[v] [um] with the history coming down from ``v_hi`` minus coming up from ``v_lo`` (normalized drive; each
    widened to the drive's own extremes). For a Preisach density of one sign every initial state's output lies
    between the two, and the difference is zero once the drive has visited both ends (wiping out)."""
    v = np.asarray(v, float)
    if v.size == 0:
        return np.zeros(0)
    lo, hi = min(float(v_lo), float(v.min())), max(float(v_hi), float(v.max()))
    top = hysteresis_parts(hp, np.concatenate([[lo, hi], v]))[0][2:]
    bottom = hysteresis_parts(hp, np.concatenate([[hi, lo], v]))[0][2:]
    return top - bottom
