"""Model kind ``refined``: hysteresis plus linear dynamics, with named physical terms added.

This is the model ``piezoctl diagnose`` writes (docs/diagnose.md). With no
terms it is the diagnosis' *base model* (``piezoctl.ident.base``): a
discretized Preisach plane (``hysteresis.type = "plane"``), followed by
discrete linear dynamics of unit static gain; ``identify --model refined``
fits that base. Each term the diagnosis adds
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
    ``type``: ``"plane"``, ``"pi"`` or ``"bouc_wen"`` (operators in
    ``piezoctl.models.hysteresis``). Plane: ``r`` play thresholds
    [normalized drive], per play ``knots`` [normalized drive] and ``values``
    [um] of its piecewise-linear function (continued linearly beyond the end
    knots), ``offset`` [um], ``v_rest``. PI: ``r`` play thresholds [normalized drive], ``w`` their weights [um],
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

import numpy as np

from ..dsp import RATE_CUTOFF_HZ, drive_rate, filt, lowpass, lowpass_tau, mode_filter, slew_limit
from ..models.hysteresis import bouc_wen_h, hysteresis_parts
from .common import IdentError

KIND = "refined"
DESCRIPTION = "hysteresis + linear dynamics with named physical terms (written by piezoctl diagnose)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "simulate_parts", "slew_limit",
           "lowpass", "mode_filter", "drive_rate", "apply_drive_terms", "filt", "TERM_ORDER"]


TERM_ORDER = ("delay", "amplifier_bandwidth", "amplifier_slew_limit", "saturation",
              "asymmetric_hysteresis", "rate_dependent_hysteresis", "creep", "unmodeled_resonance",
              "cross_coupling", "thermal_drift", "sensor_offset", "sensor_nonlinearity")


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--refined-``)."""
    parser.add_argument("--refined-settle-s", type=float, default=0.5, metavar="S",
                        help="seconds at the start of each recording left out of the fit (default 0.5)")


def fit(recordings, options) -> dict:
    """Fit the diagnosis' base model (no terms) to recordings: :func:`piezoctl.ident.base.fit_base`, the same
    fit ``piezoctl diagnose`` runs on its calibration."""
    from .base import fit_base
    settle = options.get("refined_settle_s", 0.5) if options is not None else 0.5
    params = fit_base(recordings, settle_s=0.5 if settle is None else float(settle))
    params.pop("base_info", None)
    return params


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
