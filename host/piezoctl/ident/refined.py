"""Model kind ``refined``: hysteresis plus linear dynamics, with named physical terms added.

This is the model ``piezoctl diagnose`` writes (docs/diagnose.md). With no
terms it is the diagnosis' *base model*: a Prandtl-Ishlinskii hysteresis
(classical play operators) with a polynomial of the drive, followed by
discrete linear dynamics of unit static gain. Each term the diagnosis adds
is a block of the C stage model (docs/stage-model.md) placed where the
stage has it::

    u -> delay -> amplifier bandwidth -> slew limit -> saturation
      -> hysteresis H (+ asymmetric polynomial, + rate-dependent width)
      -> creep (Kelvin-Voigt chain) -> dynamics G (+ extra mode)
      -> + coupling from u2 -> + thermal drift -> + sensor offset
      -> sensor nonlinearity -> y

Parameters (JSON, physical units where they have one)
-----------------------------------------------------
``fs_hz``
    Sample rate [Hz] the discrete dynamics were fitted at; ``simulate``
    refuses another rate (more than 1 % apart).
``u_mid``, ``u_half``
    Drive normalization [V]: ``v = (u - u_mid) / u_half``.
``hysteresis``
    ``type``: ``"pi"`` or ``"bouc_wen"``. PI: ``r`` play thresholds [normalized drive], ``w`` their weights [um],
    ``poly`` [um] coefficients of ``v, v^2, v^3``, evaluated with ``v``
    clamped to ``[v_lo, v_hi]`` (the calibration range) and continued
    linearly outside it with the cubic's mean slope over that range, ``offset`` [um], ``v_rest`` [normalized drive]: the
    plays start relaxed at the rest drive (0 V: a stage is powered up from
    0 V), so the first sample is reached along the initial loading curve.
    Bouc-Wen: ``beta``, ``gamma`` [1/normalized drive], ``c_h`` [um] (the
    weight of the hysteretic state h, alpha = 1), ``poly``, ``v_lo``, ``v_hi``,
    ``offset``, ``v_rest`` as for PI.
``dynamics``
    ``b``, ``a``: discrete transfer function at ``fs_hz`` (``a[0] = 1``),
    static gain 1; ``[1], [1]`` for a static model.
``terms``
    Object keyed by the vocabulary name, each with its parameters:

    - ``delay``: ``samples`` (may be fractional; linear interpolation).
    - ``amplifier_bandwidth``: ``hz`` (first-order low-pass on the drive).
    - ``amplifier_slew_limit``: ``v_per_s`` (rate limit of the drive).
    - ``saturation``: ``lo_v``, ``hi_v`` (clip of the drive; null = no limit).
    - ``asymmetric_hysteresis``: ``c2_um``, ``c3_um`` on ``s = (u - mid) / half``
      with the term's own ``mid_v``, ``half_v``.
    - ``rate_dependent_hysteresis``: ``gain`` [1] and ``ref_fs_per_s``: the
      hysteretic part of H is scaled by ``1 + gain r / (r + ref)``, r the
      magnitude of the normalized drive rate [FS/s] low-passed at
      ``rate_cutoff_hz``.
    - ``creep``: ``tau_s`` (list), ``gain`` (list, [1]), ``static_gain`` [1]
      and ``h_ref_um``: ``w + sum g_i (lowpass_tau_i(w) - w) + g_s (w - h_ref)``
      (g_s: the static gain the calibration, faster than the slow terms, did
      not see; h_ref: the mean H output during calibration).
    - ``unmodeled_resonance``: ``freq_hz``, ``damping``, ``gain`` [1] and
      optional ``gain_lead`` [1]: y becomes ``y + gain (M(y) - y) +
      gain_lead (z M(y) - y)``, M a unit-gain second-order mode (ZOH), z M
      the same mode without the ZOH's one-sample delay (their mix places
      the ring between two samples).
    - ``cross_coupling``: ``c_static_um_per_v``, ``c_accel_um_per_v_s2``,
      ``c_pos_per_um_v`` and ``y_center_um``: ``x = G u2`` (this axis'
      dynamics as a proxy for the other's), ``y += c_s x + c_a x'' +
      c_p x (y - y_center)``.
      Optional ``mode_hz``, ``mode_damping``, ``c_accel_lead_um_per_v_s2``: the
      acceleration is taken after a mode filter (the other axis moves through a
      resonance), with and without the ZOH's one-sample delay.
    - ``thermal_drift``: ``amplitude_um``, ``tau_s``, ``slope_um_per_s``:
      ``A (1 - exp(-(t - t0)/tau)) + slope (t - t0)``.
    - ``sensor_offset``: ``offset_um`` (used by ``simulate``) and
      ``per_recording`` (the fitted value per recording, for reading).
    - ``sensor_nonlinearity``: ``c2_um``, ``c3_um`` on ``q = (y - mid) / half``
      with ``mid_um``, ``half_um``.

Initial state: plays relaxed (output 0), every filter at the equilibrium of
its first input sample.
"""

from __future__ import annotations

import collections
import hashlib
import math

import numpy as np
from scipy import signal

from ..models.play import play_outputs
from .common import IdentError

KIND = "refined"
DESCRIPTION = "hysteresis + linear dynamics with named physical terms (written by piezoctl diagnose)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "simulate_parts", "slew_limit",
           "lowpass", "mode_filter", "drive_rate", "apply_drive_terms", "filt", "TERM_ORDER"]

TERM_ORDER = ("delay", "amplifier_bandwidth", "amplifier_slew_limit", "saturation",
              "asymmetric_hysteresis", "rate_dependent_hysteresis", "creep", "unmodeled_resonance",
              "cross_coupling", "thermal_drift", "sensor_offset", "sensor_nonlinearity")

RATE_CUTOFF_HZ = 50.0


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--refined-``)."""
    parser.add_argument("--refined-plays", type=int, default=None,
                        help="number of play operators of the base hysteresis (default 10)")


def fit(recordings, options) -> dict:
    """Fit the base model (no terms) to recordings; see :func:`piezoctl.diagnose.base.fit_base`."""
    from ..diagnose.base import fit_base
    n = options.get("refined_plays") if options is not None else None
    return fit_base(recordings, n_plays=int(n) if n else 10)


def filt(b, a, x) -> np.ndarray:
    """``lfilter(b, a, x)`` starting at the equilibrium of ``x[0]`` (static gain ``sum b / sum a``)."""
    b = np.asarray(b, float)
    a = np.asarray(a, float)
    x = np.asarray(x, float)
    if b.size == 1 and a.size == 1:
        return x * (b[0] / a[0])
    zi = signal.lfilter_zi(b, a)
    if x.ndim == 1:
        return signal.lfilter(b, a, x, zi=zi * x[0])[0]
    return signal.lfilter(b, a, x, axis=0, zi=zi[:, None] * x[0][None, :])[0]


def lowpass(x, hz: float, dt: float) -> np.ndarray:
    """First-order low-pass (pole ``hz`` [Hz], exact for a held input), from equilibrium."""
    c = 1.0 - np.exp(-2.0 * np.pi * float(hz) * dt)
    return filt([c], [1.0, c - 1.0], x)


def lowpass_tau(x, tau_s: float, dt: float) -> np.ndarray:
    """First-order low-pass with time constant ``tau_s`` [s], from equilibrium."""
    c = 1.0 - np.exp(-dt / float(tau_s))
    return filt([c], [1.0, c - 1.0], x)


def mode_filter(freq_hz: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (zero-order hold) unit-gain mode ``w^2 / (s^2 + 2 z w s + w^2)``: (b, a)."""
    w = 2.0 * np.pi * float(freq_hz)
    bd, ad, _ = signal.cont2discrete(([w * w], [1.0, 2.0 * damping * w, w * w]), dt, method="zoh")
    bd = np.ravel(bd)
    return bd, np.ravel(ad)


def slew_limit(u, max_step: float) -> np.ndarray:
    """Limit the change of ``u`` per sample to ``max_step`` (the amplifier's slew rate times dt).

    Only the stretches where the limit acts are stepped in Python; the rest is copied.
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
    while i < n:
        d = u[i] - prev
        if d > max_step:
            prev += max_step
        elif d < -max_step:
            prev -= max_step
        else:
            prev = float(u[i])
            out[i] = prev
            k = int(np.searchsorted(viol, i, side="right"))
            if k >= viol.size:
                break
            i = int(viol[k])
            prev = float(out[i - 1])
            continue
        out[i] = prev
        i += 1
    return out


def drive_rate(v, dt: float, cutoff_hz: float = RATE_CUTOFF_HZ) -> np.ndarray:
    """Magnitude of the drive rate [FS/s], low-passed at ``cutoff_hz`` [Hz]."""
    r = np.abs(np.gradient(np.asarray(v, float), dt)) if len(v) > 1 else np.zeros(len(v))
    return lowpass(r, cutoff_hz, dt)


def apply_drive_terms(terms: dict, u, dt: float) -> np.ndarray:
    """The drive after delay, amplifier bandwidth, slew limit and saturation [V]."""
    u = np.asarray(u, dtype=float)
    if "delay" in terms:
        d = float(terms["delay"]["samples"])
        if d > 0:
            idx = np.arange(u.size) - d
            u = np.interp(idx, np.arange(u.size), u, left=u[0])
    if "amplifier_bandwidth" in terms:
        u = lowpass(u, terms["amplifier_bandwidth"]["hz"], dt)
    if "amplifier_slew_limit" in terms:
        u = slew_limit(u, float(terms["amplifier_slew_limit"]["v_per_s"]) * dt)
    if "saturation" in terms:
        s = terms["saturation"]
        lo = -np.inf if s.get("lo_v") is None else float(s["lo_v"])
        hi = np.inf if s.get("hi_v") is None else float(s["hi_v"])
        u = np.clip(u, lo, hi)
    return u


def _poly_clamped(v, poly, v_lo, v_hi) -> np.ndarray:
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


_STATE_CACHE: "collections.OrderedDict" = collections.OrderedDict()
_STATE_CACHE_MAX_SAMPLES = 20_000_000   # about 160 MB of float64


def _cached_state(kind: str, params: tuple, v: np.ndarray, compute) -> np.ndarray:
    """The hysteresis state for drive ``v`` from a small LRU cache keyed on the parameters and the drive's bytes.

    The diagnosis runs the same operator on the same drive many times (per fold and round, for every setting of
    a drive-side term, on the calibration for each refit of the dynamics); the state depends only on the drive
    and the operator's shape parameters, not on the weights that change between those runs. Returns a read-only
    array (callers must not modify it)."""
    v = np.ascontiguousarray(v, dtype=float)
    key = (kind, params, v.size, hashlib.blake2b(v.view(np.uint8), digest_size=16).digest())
    hit = _STATE_CACHE.get(key)
    if hit is not None:
        _STATE_CACHE.move_to_end(key)
        return hit
    out = compute(v)
    out.setflags(write=False)
    _STATE_CACHE[key] = out
    total = sum(a.size for a in _STATE_CACHE.values())
    while total > _STATE_CACHE_MAX_SAMPLES and len(_STATE_CACHE) > 1:
        total -= _STATE_CACHE.popitem(last=False)[1].size
    return out


def bouc_wen_h(v, beta: float, gamma: float, v_rest: float = 0.0) -> np.ndarray:
    """Hysteretic state of a Bouc-Wen element (see :func:`_bouc_wen_h`), cached: read-only result."""
    return _cached_state("bw", (float(beta), float(gamma), float(v_rest)), v,
                         lambda x: _bouc_wen_h(x, float(beta), float(gamma), float(v_rest)))


def _bouc_wen_h(v, beta: float, gamma: float, v_rest: float = 0.0) -> np.ndarray:
    """Hysteretic state h of a Bouc-Wen element with alpha = 1 along the drive path v.

    ``dh = dv - beta |dv| h - gamma dv |h|`` (``beta > |gamma|``), starting at h = 0 at
    ``v_rest``. Rate independent: within a monotone run of the drive (direction s) h is a
    closed-form function of the path length L travelled in the run,
    ``h = heq + (h0 - heq) exp(-k L)``, ``k = beta + s sign(h) gamma``, ``heq = s / k``;
    when h starts against the direction it reaches zero after
    ``l0 = log(1 - h0 / heq) / k`` and continues with ``k = beta + gamma``. Evaluated
    exactly at every sample, one run at a time (a drive step of any size is exact).
    """
    v = np.concatenate([[v_rest], np.asarray(v, float)])
    dv = np.diff(v)
    out = np.zeros(dv.size)
    nz = np.flatnonzero(dv != 0.0)
    if nz.size == 0:
        return out
    sgn = np.sign(dv[nz])
    # run starts: first nonzero step and every change of direction; zero steps belong to the run before them
    starts = nz[np.concatenate([[0], np.flatnonzero(sgn[1:] != sgn[:-1]) + 1])]
    ends = np.append(starts[1:], dv.size)
    path = np.cumsum(np.abs(dv))
    h0 = 0.0
    hs = []
    kp, km = beta + gamma, beta - gamma
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


def hysteresis_parts(hp: dict, v) -> tuple[np.ndarray, np.ndarray]:
    """(H[v] without offset, hysteretic part) [um] for normalized drive v.

    ``type`` ``"pi"`` (default): plays, hysteretic part ``sum w_i (P_i(v) - v)``;
    ``"bouc_wen"``: ``c_h h(v; beta, gamma) + poly(v)``, hysteretic part ``c_h h``.
    """
    if hp.get("type", "pi") == "bouc_wen":
        hh = float(hp["c_h"]) * bouc_wen_h(v, float(hp["beta"]), float(hp["gamma"]), float(hp.get("v_rest", 0.0)))
        return hh + _poly_clamped(v, hp["poly"], hp["v_lo"], hp["v_hi"]), hh
    r = np.asarray(hp["r"], float)
    w = np.asarray(hp["w"], float)
    v_rest = float(hp.get("v_rest", 0.0))
    P = (_cached_state("play", (tuple(r.tolist()), v_rest), v, lambda x: play_outputs(x, r, y0=np.full(r.size, v_rest)))
         if v.size else np.zeros((0, r.size)))
    hyst = P @ w - float(w.sum()) * v
    out = float(w.sum()) * v + hyst + _poly_clamped(v, hp["poly"], hp["v_lo"], hp["v_hi"])
    return out, hyst


def _check_rate(params, t) -> float:
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0 / float(params["fs_hz"])
    fs = 1.0 / dt
    if abs(fs / float(params["fs_hz"]) - 1.0) > 0.01:
        raise IdentError(f"refined: the model's dynamics are for {params['fs_hz']:g} Hz, the input is "
                         f"sampled at {fs:g} Hz")
    return dt


def simulate_parts(params: dict, t, u, u2=None) -> dict:
    """Run the model and return its intermediate signals.

    Returns
    -------
    dict
        ``u_eff`` drive after the drive terms [V], ``v`` normalized drive,
        ``h`` H output [um] (no offset), ``hyst`` its hysteretic part [um],
        ``w`` after creep [um], ``y_dyn`` after the dynamics and any extra mode
        [um], ``y`` the model output [um].
    """
    terms = params.get("terms", {}) or {}
    unknown = set(terms) - set(TERM_ORDER)
    if unknown:
        raise IdentError(f"refined: unknown terms {sorted(unknown)}; known: {', '.join(TERM_ORDER)}")
    t = np.asarray(t, float)
    dt = _check_rate(params, t)
    ue = apply_drive_terms(terms, u, dt)
    v = (ue - float(params["u_mid"])) / float(params["u_half"])
    hp = params["hysteresis"]
    h, hyst = hysteresis_parts(hp, v)
    if "asymmetric_hysteresis" in terms:
        a = terms["asymmetric_hysteresis"]
        s = (ue - float(a["mid_v"])) / float(a["half_v"])
        h = h + float(a["c2_um"]) * s ** 2 + float(a["c3_um"]) * s ** 3
    if "rate_dependent_hysteresis" in terms:
        rd = terms["rate_dependent_hysteresis"]
        r = drive_rate(v, dt, float(rd.get("rate_cutoff_hz", RATE_CUTOFF_HZ)))
        h = h + float(rd["gain"]) * r / (r + float(rd["ref_fs_per_s"])) * hyst
    w = h
    if "creep" in terms:
        c = terms["creep"]
        w = h + sum(float(g) * (lowpass_tau(h, tau, dt) - h) for tau, g in zip(c["tau_s"], c["gain"])) \
            + float(c.get("static_gain", 0.0)) * (h - float(c.get("h_ref_um", 0.0)))
    dyn = params["dynamics"]
    y = filt(dyn["b"], dyn["a"], w)
    if "unmodeled_resonance" in terms:
        m = terms["unmodeled_resonance"]
        bm, am = mode_filter(m["freq_hz"], m["damping"], dt)
        yi = y
        y = y + float(m["gain"]) * (filt(bm, am, yi) - yi)
        if float(m.get("gain_lead", 0.0)) != 0.0:  # the mode without the ZOH's one-sample delay
            y = y + float(m["gain_lead"]) * (filt(bm[1:], am, yi) - yi)
    y_dyn = y
    y = y + float(hp.get("offset", 0.0))
    if "cross_coupling" in terms and u2 is not None:
        c = terms["cross_coupling"]
        x = filt(dyn["b"], dyn["a"], np.asarray(u2, float))
        xa = x
        acc_lead = 0.0
        if c.get("mode_hz"):  # the other axis moves through a mode: its acceleration rings
            bm, am = mode_filter(float(c["mode_hz"]), float(c["mode_damping"]), dt)
            xa = filt(bm, am, x)
            acc_lead = np.gradient(np.gradient(filt(bm[1:], am, x), dt), dt)  # the mode without the ZOH delay
        acc = np.gradient(np.gradient(xa, dt), dt)
        y = y + float(c.get("c_accel_lead_um_per_v_s2", 0.0)) * acc_lead
        y = y + float(c["c_static_um_per_v"]) * (x - float(c.get("u2_ref_v", 0.0))) \
            + float(c["c_accel_um_per_v_s2"]) * acc \
            + float(c["c_pos_per_um_v"]) * (x - float(c.get("u2_ref_v", 0.0))) * (y - float(c["y_center_um"]))
    if "thermal_drift" in terms:
        th = terms["thermal_drift"]
        tt = t - t[0]
        y = y + float(th["amplitude_um"]) * (1.0 - np.exp(-tt / float(th["tau_s"]))) \
            + float(th.get("slope_um_per_s", 0.0)) * tt
    if "sensor_offset" in terms:
        y = y + float(terms["sensor_offset"]["offset_um"])
    if "sensor_nonlinearity" in terms:
        sn = terms["sensor_nonlinearity"]
        q = (y - float(sn["mid_um"])) / float(sn["half_um"])
        y = y + float(sn["c2_um"]) * q ** 2 + float(sn["c3_um"]) * q ** 3
    return {"u_eff": ue, "v": v, "h": h, "hyst": hyst, "w": w, "y_dyn": y_dyn, "y": y}


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V] at times t [s]; ``u2`` [V] feeds a coupling term."""
    return simulate_parts(params, t, u, u2)["y"]
