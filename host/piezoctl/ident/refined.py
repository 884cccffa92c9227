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
      with the term's own ``mid_v``, ``half_v``; with ``side`` (+1, -1) and
      ``knee_v`` on ``x = max(side (u - knee_v), 0) / half_v`` instead (one end
      of the stroke only); with ``backlash_v`` (round 15) u is first the play
      of the drive of that half-width [V], relaxed at the first sample.
    - ``rate_dependent_hysteresis``: ``gain`` [1], ``ref_fs_per_s`` and
      ``width_k`` [1] (round 15): every play of the plane has its threshold
      multiplied by ``1 + width_k r / (r + ref)`` (a play keeps the threshold
      it last moved with), and H changes by ``gain`` times the change this
      makes; r the magnitude of the normalized drive rate [FS/s] low-passed
      at ``rate_cutoff_hz``. Without ``width_k`` (files of rounds up to 14)
      the hysteretic part of H is scaled by ``1 + gain r / (r + ref)``.
      Round 16: ``constant_k`` and ``constant_gain`` (lists): H also changes
      by ``sum constant_gain_i`` times the change of every play's threshold
      x (1 + constant_k_i) (the constant widening the term was nested
      against, refitted with it); with ``widen_bw`` true a Bouc-Wen column of
      the plane is scaled by the same width factor, ``(w - 1) c_h h(v)``.
      Round 24: ``width_k`` < 0 is a narrowing: every play's threshold is
      ``max(r_j + width_k x / (x + ref), 0)`` (moved in by the same amount
      for every play), ``x = max(r - rate_floor_fs_per_s, 0)`` the rate
      beyond the calibration's fastest [FS/s], H changes by ``gain`` times
      the change; a Bouc-Wen column is not changed.
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
      ``A (1 - exp(-(t - t0)/tau)) + slope (t - t0)`` for ``t >= t0`` (0 before).
      With ``t0_session_s`` the clock is the session's (``t`` = the recording's
      ``session_time_s`` + its time, ``t0`` = ``t0_session_s``: the drift runs on
      wall time across recordings); without it, ``t0`` is each recording's start.
    - ``sensor_offset``: ``offset_um`` (used by ``simulate``) and
      ``per_recording`` (the fitted value per recording, for reading).
    - ``sensor_nonlinearity``: ``c2_um``, ``c3_um`` on ``q = (y - mid) / half``
      with ``mid_um``, ``half_um``.

Initial state: plays relaxed (output 0), every filter at the equilibrium of
its first input sample.
"""

from __future__ import annotations

import numpy as np

from ..dsp import drive_rate, filt, lowpass, mode_filter, slew_limit
from ..models.hysteresis import bouc_wen_h, hysteresis_parts
from .common import IdentError
from .terms import TERM_ORDER, TERMS, G, SimState

KIND = "refined"
DESCRIPTION = "hysteresis + linear dynamics with named physical terms (written by piezoctl diagnose)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "simulate_parts", "TERM_ORDER",
           # re-exported for model users: the filters (piezoctl.dsp) and the Bouc-Wen state
           "slew_limit", "lowpass", "mode_filter", "drive_rate", "filt", "bouc_wen_h"]


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


def _check_rate(params, t) -> float:
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0 / float(params["fs_hz"])
    fs = 1.0 / dt
    if abs(fs / float(params["fs_hz"]) - 1.0) > 0.01:
        raise IdentError(f"refined: the model's dynamics are for {params['fs_hz']:g} Hz, the input is "
                         f"sampled at {fs:g} Hz")
    return dt


def simulate_parts(params: dict, t, u, u2=None, t_session=None) -> dict:
    """Run the model and return its intermediate signals.

    ``t_session`` [s]: the recording's first sample on the session clock (metadata ``session_time_s``), for
    terms that run on it (thermal drift fitted on session time); None: such a term starts with the recording.

    The terms are applied stage by stage in :data:`piezoctl.ident.terms.TERM_ORDER`, each by its own
    :class:`~piezoctl.ident.terms.Term` class (the same code whose linearization the diagnosis tested).

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
    st = SimState(params=params, t=t, dt=_check_rate(params, t), u=np.asarray(u, float),
                  u2=None if u2 is None else np.asarray(u2, float), t_session=t_session)
    order = [n for n in TERM_ORDER if n in terms]

    def stage(name):
        for n in order:
            if TERMS[n].stage == name:
                TERMS[n].apply(terms[n], st)

    st.ue = st.u
    stage("drive")
    st.v = (st.ue - float(params["u_mid"])) / float(params["u_half"])
    hp = params["hysteresis"]
    st.h, st.hyst = hysteresis_parts(hp, st.v)
    stage("hysteresis")
    st.w = st.h
    stage("creep")
    st.y = G(params, st.w)
    stage("dynamics")
    y_dyn = st.y
    st.y = st.y + float(hp.get("offset", 0.0))
    stage("output")
    return {"u_eff": st.ue, "v": st.v, "h": st.h, "hyst": st.hyst, "w": st.w, "y_dyn": y_dyn, "y": st.y}


def simulate(params: dict, t, u, u2=None, t_session=None) -> np.ndarray:
    """Model output y [um] for drive u [V] at times t [s]; ``u2`` [V] feeds a coupling term; ``t_session`` [s]
    the recording's start on the session clock (see :func:`simulate_parts`)."""
    return simulate_parts(params, t, u, u2, t_session)["y"]
