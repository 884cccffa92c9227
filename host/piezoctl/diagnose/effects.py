"""The vocabulary: one entry per missing-physics effect, with its signature and model term.

Every effect is a family of regressors computed from the base model's signals (its
drive, H output, hysteretic part, output) and the recording (t, u2). Given a setting of
the effect's nonlinear parameter (a time constant, a frequency, a limit; searched on a
grid on the training data only), the term is *linear* in its coefficients, so adding it
to the model is a least-squares problem on the residual. The drive-side
dynamics terms (delay, bandwidth, slew limit) are simulated exactly with the base
dynamics refitted on the calibration (see below); saturation is linearized around the
base model for the search; the refined model applies every term exactly and its
held-out error is computed by simulation.

``where`` describes, from the fitted contribution, where the effect acts; ``evidence``
is one sentence for the user.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from ..dsp import RATE_CUTOFF_HZ, drive_rate, filt, lowpass, lowpass_tau, mode_filter, slew_limit
from ..models.hysteresis import hysteresis_channels, hysteresis_parts, scale_channels

__all__ = ["VOCABULARY", "Effect", "EFFECTS", "Signals", "nuisance_columns"]

VOCABULARY = ("creep", "thermal_drift", "sensor_offset", "cross_coupling", "rate_dependent_hysteresis",
              "unmodeled_resonance", "delay", "amplifier_slew_limit", "amplifier_bandwidth",
              "sensor_nonlinearity", "saturation", "asymmetric_hysteresis")


@dataclasses.dataclass
class Signals:
    """One recording with the base model's signals (all arrays of the recording's length)."""

    name: str
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    u2: np.ndarray | None
    x2: np.ndarray | None
    temp: np.ndarray | None
    dt: float
    v: np.ndarray          # normalized drive of the base model
    h: np.ndarray          # H output [um]
    hyst: np.ndarray       # hysteretic part of H [um]
    yb: np.ndarray         # base model output [um]
    ydyn: np.ndarray       # base output before the offset [um]
    index: int = 0


@dataclasses.dataclass
class Effect:
    """A vocabulary entry.

    ``settings(ctx)`` lists the nonlinear parameter values to search;
    ``regressors(ctx, s, setting)`` gives the (n, k) regressors for one recording;
    ``term(ctx, setting, coef)`` turns a fit into the refined model's term parameters;
    ``describe(ctx, setting, coef)`` gives the fitted values with units (dict) and a
    phrase for the evidence sentence.
    """

    name: str
    signature: str
    settings: Callable
    regressors: Callable
    term: Callable
    describe: Callable
    applicable: Callable = lambda ctx: True
    group: str = ""      # effects of one group refit the same part of the base; at most one is accepted
    # number of leading regressor columns that are a nuisance (refit of the base's own structure): the term is
    # tested against the model with the nuisance alone refitted on the same fold (a nested test)
    nuisance: Callable = lambda ctx: 0
    # the last regressor column is a constant (the model's offset refitted with the term), also a nuisance: a
    # term that shifts the mean output must not leave a constant behind for "sensor_offset" to claim
    intercept: bool = False
    # finer settings around the best one so far at refinement level 1, 2 (the grid's neighbours' midpoints, then
    # halfway again), tried on the same training data; empty when the grid is fine enough
    refine: Callable = lambda ctx, setting, level: []
    # lower bounds of the coefficients (None: unconstrained), e.g. creep gains >= 0 (a Kelvin-Voigt element only
    # adds compliance; free signs turn the chain into an arbitrary slow filter)
    lower: Callable = lambda ctx: None
    # tested nested against free gains on the current model's hysteresis channels through its dynamics, refitted
    # on the same fold (run.hysteresis_nuisance): what a refit of the base could absorb is not credited to the
    # term. Creep carries a richer nuisance of its own (every feature of the hysteresis).
    nested: bool = True


def _G(ctx, x):
    return filt(ctx.base["dynamics"]["b"], ctx.base["dynamics"]["a"], x)


# --- creep -----------------------------------------------------------------------------
# creep time constants [s]: from 0.1 s up (a faster "creep" is a lag of the dynamics, not creep)
CREEP_TAUS = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0)


def _creep_taus(ctx):
    return [tau for tau in CREEP_TAUS if tau < 2.0 * ctx.duration]


def _hfeatures(ctx, u):
    """The current hysteresis' channels for drive u [V] plus a constant (see
    :func:`piezoctl.models.hysteresis.hysteresis_channels`): free gains on them refit the base's own flexibility."""
    v = (np.asarray(u, float) - float(ctx.base["u_mid"])) / float(ctx.base["u_half"])
    return np.column_stack([hysteresis_channels(ctx.base["hysteresis"], v), np.ones(v.size)])


def _creep_reg(ctx, s, setting):
    # leading columns: the base hysteresis' own features through G (the nuisance: the hysteresis refitted with the
    # chain, since a fast calibration turned part of a slow creep into a mean level and a wider loop); then per
    # time constant the chain's deviation lowpass_tau(h) - h through G: a transient after steps and dwells
    F = _hfeatures(ctx, s.u)
    cols = [_G(ctx, F[:, j]) for j in range(F.shape[1] - 1)]
    cols += [_G(ctx, lowpass_tau(s.h, tau, s.dt) - s.h) for tau in _creep_taus(ctx)]
    return np.column_stack(cols + [np.ones(s.t.size)])


def _creep_nuisance(ctx):
    return _hfeatures(ctx, np.zeros(2)).shape[1] - 1


def _creep_split(ctx, coef):
    n = _creep_nuisance(ctx)
    c = np.asarray(coef, float)
    return np.concatenate([c[:n], c[-1:]]), c[n:-1]


def _creep_lower(ctx):
    n = _creep_nuisance(ctx)
    return np.concatenate([np.full(n, -np.inf), np.zeros(len(_creep_taus(ctx))), [-np.inf]])


def _creep_term(ctx, setting, coef):
    """w = h + sum g_i (lp_i(h) - h): the refined kind's chain, with the base hysteresis' weights changed by the
    jointly fitted nuisance coefficients Q (plays or Bouc-Wen weight, drive cubic, offset)."""
    taus = _creep_taus(ctx)
    Q, g = _creep_split(ctx, coef)
    hp = scale_channels(ctx.base["hysteresis"], Q[:-1])
    hp["offset"] = float(hp.get("offset", 0.0)) + float(Q[-1])
    return {"tau_s": list(taus), "gain": [float(c) for c in g], "static_gain": 0.0, "h_ref_um": 0.0,
            "_hysteresis": hp}


def _creep_desc(ctx, setting, coef):
    taus = _creep_taus(ctx)
    g = _creep_split(ctx, coef)[1]
    main = taus[int(np.argmax(np.abs(g)))]
    return ({"tau_s": taus, "gain": [round(float(c), 5) for c in g], "total_gain": round(float(g.sum()), 5)},
            f"the residual follows the low-passed drive history (Kelvin-Voigt creep, total {100 * g.sum():.2f} % "
            f"of the hysteresis output, strongest time constant {main:g} s), largest in the seconds after a step")


# --- thermal drift ---------------------------------------------------------------------
THERMAL_TAUS = (5.0, 15.0, 50.0, 150.0, 500.0)


def _th_reg(ctx, s, tau):
    tt = s.t - s.t[0]
    return np.column_stack([1.0 - np.exp(-tt / tau), tt])


def _th_term(ctx, tau, coef):
    return {"amplitude_um": float(coef[0]), "tau_s": float(tau), "slope_um_per_s": float(coef[1])}


def _th_desc(ctx, tau, coef):
    return ({"amplitude_um": round(float(coef[0]), 4), "tau_s": tau, "slope_um_per_s": float(coef[1])},
            f"the residual drifts with time since the start of each recording ({coef[0]:+.3f} um with time "
            f"constant {tau:g} s, {coef[1] * 60:+.3f} um/min), whatever the drive does")


# --- sensor offset ---------------------------------------------------------------------
def _off_reg(ctx, s, setting):
    X = np.zeros((s.t.size, ctx.n_rec))
    X[:, s.index] = 1.0
    return X


def _off_term(ctx, setting, coef):
    per = {n: float(c) for n, c in zip(ctx.names, coef)}
    return {"offset_um": float(np.mean(coef)), "per_recording": per}


def _off_desc(ctx, setting, coef):
    per = {n: round(float(c), 4) for n, c in zip(ctx.names, coef)}
    return ({"offset_um_per_recording": per},
            "the residual is a constant per recording (" + ", ".join(f"{n}: {c:+.3f} um" for n, c in per.items())
            + "): the sensor's zero moved between sessions")


# --- cross coupling --------------------------------------------------------------------
def _cc_app(ctx):
    return any(s.u2 is not None and np.ptp(s.u2) > 1e-6 for s in ctx.signals)


def _cc_settings(ctx):
    # None: the other axis follows G; (f, zeta): it moves through a mode at a residual peak, so the acceleration
    # it couples in rings (a step of u2 through a stiff axis is a burst at the mode, not a two-sample spike)
    return [None] + [(f, z) for f in ctx.peak_freqs for z in DAMPINGS]


def _cc_reg(ctx, s, setting):
    n = s.t.size
    k = 3 if setting is None else 4
    if s.u2 is None:
        return np.zeros((n, k))
    xg = _G(ctx, s.u2)
    x = xg - ctx.u2_ref
    cols = [x, None, x * (s.yb - ctx.y_center)]
    if setting is not None:
        # with and without the ZOH's one-sample delay (as the resonance term): at 1.5 kHz and 10 kHz one sample is
        # 54 degrees of the ring
        bm, am = mode_filter(setting[0], setting[1], s.dt)
        cols.append(np.gradient(np.gradient(filt(bm[1:], am, xg), s.dt), s.dt))
        xg = filt(bm, am, xg)
    cols[1] = np.gradient(np.gradient(xg, s.dt), s.dt)
    return np.column_stack(cols)


def _cc_term(ctx, setting, coef):
    out = {"c_static_um_per_v": float(coef[0]), "c_accel_um_per_v_s2": float(coef[1]),
           "c_pos_per_um_v": float(coef[2]), "y_center_um": float(ctx.y_center), "u2_ref_v": float(ctx.u2_ref)}
    if setting is not None:
        out.update(mode_hz=float(setting[0]), mode_damping=float(setting[1]), c_accel_lead_um_per_v_s2=float(coef[3]))
    return out


def _cc_desc(ctx, setting, coef):
    par = {"static_um_per_v": float(coef[0]), "accel_um_per_v_s2": float(coef[1]),
           "position_dependence_per_um_v": float(coef[2])}
    ring = ""
    if setting is not None:
        par.update(other_axis_mode_hz=round(setting[0], 1), other_axis_mode_damping=setting[1])
        ring = f", ringing at {setting[0]:.0f} Hz after the other axis' steps (it moves through that mode)"
    return (par, f"the residual follows the other axis' motion (u2): {1000 * coef[0]:+.2f} nm per volt of u2 plus a "
                 f"term in its acceleration, i.e. coupling that grows with frequency{ring}")


# --- rate-dependent hysteresis -----------------------------------------------------------
RATE_REFS = (0.3, 1.0, 3.0, 10.0, 30.0, 100.0)  # FS/s


def _rd_reg(ctx, s, ref):
    r = drive_rate(s.v, s.dt, RATE_CUTOFF_HZ)
    return _G(ctx, r / (r + ref) * s.hyst)[:, None]


def _rd_term(ctx, ref, coef):
    return {"gain": float(coef[0]), "ref_fs_per_s": float(ref), "rate_cutoff_hz": RATE_CUTOFF_HZ}


def _rd_desc(ctx, ref, coef):
    vps = ref * ctx.base["u_half"]
    return ({"gain": round(float(coef[0]), 4), "ref_v_per_s": round(vps, 1)},
            f"the hysteresis loop widens with the drive rate (width x (1 + {coef[0]:.2f} r / (r + {vps:.0f} V/s))); "
            f"the residual grows with |du/dt| and changes sign with the direction")


# --- unmodeled resonance -----------------------------------------------------------------
DAMPINGS = (0.005, 0.01, 0.02, 0.05)


def _res_settings(ctx):
    # around each residual peak (Welch bins are 2.4 Hz; a damped ring's peak is not exactly its mode frequency)
    return [(f * q, z) for f in ctx.peak_freqs for q in (0.97, 0.98, 0.99, 1.0, 1.01, 1.02, 1.03) for z in DAMPINGS]


def _res_reg(ctx, s, setting):
    f, z = setting
    bm, am = mode_filter(f, z, s.dt)
    # the mode with and without the ZOH's one-sample delay: the ring's timing within a sample is not known
    return np.column_stack([filt(bm, am, s.ydyn) - s.ydyn, filt(bm[1:], am, s.ydyn) - s.ydyn])


def _res_term(ctx, setting, coef):
    return {"freq_hz": float(setting[0]), "damping": float(setting[1]), "gain": float(coef[0]),
            "gain_lead": float(coef[1])}


def _res_desc(ctx, setting, coef):
    return ({"freq_hz": round(setting[0], 1), "damping": setting[1], "gain": round(float(coef[0] + coef[1]), 4)},
            f"the residual rings at {setting[0]:.0f} Hz (damping {setting[1]:g}) after fast edges and triangle "
            f"corners, above the calibration's band: a mode with {100 * (coef[0] + coef[1]):.1f} % of the static gain")


def _res_app(ctx):
    return bool(ctx.peak_freqs)


# --- drive-side dynamics: delay, amplifier bandwidth, slew limit -----------------------------
# These change the phase and shape of fast motion, which the base model's dynamics (fitted on
# the calibration) partly absorb: a 1 ms delay seen only below 20 Hz is fitted as a lag. So each
# setting is tried *as the base model would have been fitted with it*: the drive term is put in
# front of the base hysteresis, the dynamics G are refitted on the calibration (ARX, order by
# the same 5 % rule as the base), and the recordings are re-simulated exactly. The regressor is
# that simulation minus the base output (coefficient ~1). The refitted G goes into the refined
# model with the term. Only the calibration enters the refit; the setting is chosen on the
# training fold of the recordings.
DELAYS = (1, 2, 3, 4, 6, 8, 10, 12, 16, 20, 25, 32, 40, 50, 64)


def _shift(x, d):
    idx = np.arange(x.size) - d
    return np.interp(idx, np.arange(x.size), x, left=x[0])


def _drive_h(ctx, name, setting, u, h_base, dt):
    """H output [um] with the drive term in front: a delay shifts H's output (exact: H is rate independent); a
    band limit or a slew limit changes the drive's path, so H is run again on the filtered drive (a low-pass of
    H's output would round the loop's corners differently from a low-passed drive through the hysteresis)."""
    if name == "delay":
        return _shift(h_base, setting)
    ue = lowpass(u, setting, dt) if name == "amplifier_bandwidth" else slew_limit(u, setting * dt)
    return _h_of_drive(ctx, ue, u, h_base)


def _h_of_drive(ctx, ue, u, h_base):
    """H output [um] of the current model's hysteresis for a changed drive ``ue`` [V]; ``h_base`` (its output
    for the unchanged drive ``u``) when the change does nothing."""
    if np.array_equal(ue, u):
        return h_base
    v = (ue - float(ctx.base["u_mid"])) / float(ctx.base["u_half"])
    return hysteresis_parts(ctx.base["hysteresis"], v)[0]


def refit_dynamics(ctx, name, setting):
    """(b, a) of G refitted on the calibration with the drive term ``name`` at ``setting`` in front."""
    key = (name, float(setting))
    if key in ctx.refit_cache:
        return ctx.refit_cache[key]
    from ..ident.base import band_cps, fit_dynamics
    if "band" not in ctx.refit_cache:  # the calibration's band hardly depends on the drive term's setting
        ctx.refit_cache["band"] = band_cps(ctx.cal_h, ctx.cal_k0)
    xs = [_drive_h(ctx, name, setting, r.u, h, r.dt) for r, h in zip(ctx.cal, ctx.cal_h)]
    off = float(ctx.base["hysteresis"].get("offset", 0.0))
    ba = fit_dynamics(xs, [np.asarray(r.y, float) - off for r in ctx.cal], ctx.cal_k0, max_rows=40_000,
                      band=ctx.refit_cache["band"])
    ctx.refit_cache[key] = ba
    return ba


def _dd_reg(name):
    def reg(ctx, s, setting):
        # the change of the dynamics' output (refitted G on the term's H output minus the current G on the current
        # H output): terms added after the dynamics (per-recording offsets, drift, coupling) cancel, where the
        # difference to the model's output would carry them into the regressor
        b, a = refit_dynamics(ctx, name, setting)
        x = _drive_h(ctx, name, setting, s.u, s.h, s.dt)
        return (filt(b, a, x) - _G(ctx, s.h))[:, None]
    return reg


def _dd_term(name, key, conv):
    def term(ctx, setting, coef):
        b, a = refit_dynamics(ctx, name, setting)
        return {key: conv(ctx, setting), "_dynamics": {"b": list(map(float, b)), "a": list(map(float, a))}}
    return term


def _del_desc(ctx, d, coef):
    return ({"samples": float(d), "seconds": d * ctx.dt},
            f"the measurement lags by {d:g} samples ({1000 * d * ctx.dt:.2f} ms) at every frequency: with this "
            f"delay in front of the model (dynamics refitted on the calibration) edges and corners line up")


def _bw_settings(ctx):
    fs = 1.0 / ctx.dt
    return [float(f) for f in np.geomspace(fs / 500.0, fs / 4.0, 14)]


def _bw_desc(ctx, fc, coef):
    return ({"hz": round(fc, 1)},
            f"the drive is low-passed before the actuator (first order, {fc:.0f} Hz; dynamics refitted on the "
            f"calibration): edges are rounded exponentially and fast content is attenuated and delayed")


def _sl_settings(ctx):
    rmax = ctx.max_step
    return [float(rmax * q) / ctx.dt for q in (0.03, 0.05, 0.1, 0.2, 0.35, 0.5, 0.7)]


def _sl_desc(ctx, vps, coef):
    return ({"v_per_s": round(vps, 1)},
            f"large fast drive changes are rate limited at about {vps / 1000:.1f} V/ms "
            f"(amplifier current limit): edges become ramps whose length grows with the step size")


def _sl_app(ctx):
    return ctx.max_step > 0


# --- saturation --------------------------------------------------------------------------
SAT_COARSE = tuple(0.025 * i for i in range(15))   # threshold below the largest drive, fraction of the span


def _sat_settings(ctx):
    lo, hi = ctx.u_lo, ctx.u_hi
    span = hi - lo
    out = [(None, hi - q * span) for q in SAT_COARSE[1:]]
    out += [(lo + q * span, None) for q in SAT_COARSE[1:]]
    return out


def _sat_h(ctx, s, setting):
    """H output [um] with the drive clipped at ``setting`` (lo, hi) [V]: the hysteresis sees the clipped drive
    (it reverses at the limit, not where the command does)."""
    lo, hi = setting
    uc = np.clip(s.u, -np.inf if lo is None else lo, np.inf if hi is None else hi)
    return _h_of_drive(ctx, uc, s.u, s.h)


def _sat_reg(ctx, s, setting):
    # exact for the base model: the output with the clipped drive minus the output without (coefficient ~1)
    return _G(ctx, _sat_h(ctx, s, setting) - s.h)[:, None]


def _sat_term(ctx, setting, coef):
    return {"lo_v": setting[0], "hi_v": setting[1]}


def _sat_desc(ctx, setting, coef):
    lo, hi = setting
    where = f"above {hi:.1f} V" if hi is not None else f"below {lo:.1f} V"
    return ({"lo_v": lo, "hi_v": hi},
            f"the displacement stops following the drive {where}: the residual is zero inside that range and "
            f"grows with the excess (a clipped drive)")


# --- sensor nonlinearity -----------------------------------------------------------------
def _sn_reg(ctx, s, setting):
    q = (s.yb - ctx.y_center) / ctx.y_half
    return np.column_stack([q ** 2, q ** 3])


def _sn_term(ctx, setting, coef):
    return {"c2_um": float(coef[0]), "c3_um": float(coef[1]), "mid_um": float(ctx.y_center),
            "half_um": float(ctx.y_half)}


def _sn_desc(ctx, setting, coef):
    return ({"c2_um": round(float(coef[0]), 4), "c3_um": round(float(coef[1]), 4)},
            f"the residual is a static function of the displacement itself ({coef[0]:+.3f} um q^2 "
            f"{coef[1]:+.3f} um q^3 over the stroke), the same on rising and falling branches at equal y")


# --- asymmetric hysteresis ---------------------------------------------------------------
def _ah_reg(ctx, s, setting):
    q = (s.u - ctx.u_mid_all) / ctx.u_half_all
    return _G(ctx, np.column_stack([q ** 2, q ** 3]))


def _ah_term(ctx, setting, coef):
    return {"c2_um": float(coef[0]), "c3_um": float(coef[1]), "mid_v": float(ctx.u_mid_all),
            "half_v": float(ctx.u_half_all)}


def _ah_desc(ctx, setting, coef):
    return ({"c2_um": round(float(coef[0]), 4), "c3_um": round(float(coef[1]), 4)},
            f"the loop is not point-symmetric: an even function of the drive ({coef[0]:+.3f} um s^2) is missing, "
            f"largest at the ends of the stroke that calibration did not reach")


def _one(ctx):
    return [None]


def _geo_refine(grid_of):
    """Refinement for a geometric grid of scalars: the two points a factor r^(1/2^level) either side of
    ``setting``, r the grid's mean ratio (level 1: the geometric midpoints to its neighbours)."""
    def refine(ctx, x, level):
        g = np.asarray(grid_of(ctx), float)
        if x is None or g.size < 2 or not np.all(g > 0):
            return []
        r = float(np.exp(np.mean(np.diff(np.log(g)))))
        if r <= 1.0:
            return []
        f = r ** (0.5 ** level)
        return [float(x) / f, float(x) * f]
    return refine


def _sat_refine(ctx, setting, level):
    lo, hi = setting
    d = 0.025 * (ctx.u_hi - ctx.u_lo) * 0.5 ** level   # the grid step halved per level
    return [(lo, hi - d), (lo, hi + d)] if hi is not None else [(lo - d, hi), (lo + d, hi)]


def nuisance_columns(eff: Effect, ctx, k: int) -> list:
    """Indices of the nuisance columns among an effect's ``k`` regressor columns: the first
    ``eff.nuisance(ctx)``, and the last when ``eff.intercept``."""
    return list(range(eff.nuisance(ctx))) + ([k - 1] if eff.intercept else [])


def _with_intercept(eff: Effect) -> Effect:
    """``eff`` with a constant column appended, fitted with it and added to the model's offset."""
    import copy

    def reg(ctx, s, st):
        X = np.asarray(eff.regressors(ctx, s, st), float)
        return np.column_stack([X, np.ones(X.shape[0])])

    def term(ctx, st, coef):
        out = dict(eff.term(ctx, st, coef[:-1]))
        hp = copy.deepcopy(out.get("_hysteresis", ctx.base["hysteresis"]))
        hp["offset"] = float(hp.get("offset", 0.0)) + float(coef[-1])
        out["_hysteresis"] = hp
        return out

    def lower(ctx):
        lb = eff.lower(ctx)
        return None if lb is None else list(lb) + [-np.inf]

    return dataclasses.replace(eff, regressors=reg, term=term, describe=lambda ctx, st, c: eff.describe(ctx, st, c[:-1]),
                               lower=lower, intercept=True)


EFFECTS = {
    "creep": Effect("creep", "residual correlated with the low-passed drive history; large after steps and dwells",
                    _one, _creep_reg, _creep_term, _creep_desc, nuisance=_creep_nuisance,
                    lower=_creep_lower, intercept=True, nested=False),
    "thermal_drift": Effect("thermal_drift", "slow trend with time (or temperature), independent of the drive",
                            lambda ctx: list(THERMAL_TAUS), _th_reg, _th_term, _th_desc),
    "sensor_offset": Effect("sensor_offset", "a constant per recording (session)", _one, _off_reg, _off_term,
                            _off_desc),
    "cross_coupling": Effect("cross_coupling", "residual explained by the other axis' drive/motion, growing "
                             "with its frequency", _cc_settings, _cc_reg, _cc_term, _cc_desc, _cc_app),
    "rate_dependent_hysteresis": _with_intercept(Effect("rate_dependent_hysteresis", "residual grows with |du/dt| times the "
                                        "hysteretic part (loop width grows with rate)",
                                        lambda ctx: list(RATE_REFS), _rd_reg, _rd_term, _rd_desc,
                                        lower=lambda ctx: [0.0])),   # loops widen with rate, never narrow
    "unmodeled_resonance": Effect("unmodeled_resonance", "residual energy in a narrow band above the calibration "
                                  "band, ringing after corners", _res_settings, _res_reg, _res_term, _res_desc,
                                  _res_app),
    "delay": Effect("delay", "a constant lag at every frequency (edges shifted, not rounded)",
                    lambda ctx: list(DELAYS), _dd_reg("delay"),
                    _dd_term("delay", "samples", lambda ctx, d: float(d)), _del_desc, group="drive_dynamics"),
    "amplifier_slew_limit": Effect("amplifier_slew_limit", "residual only where |du/dt| exceeds a limit; "
                                   "edges become ramps", _sl_settings, _dd_reg("amplifier_slew_limit"),
                                   _dd_term("amplifier_slew_limit", "v_per_s", lambda ctx, x: float(x)),
                                   _sl_desc, _sl_app, group="drive_dynamics", refine=_geo_refine(_sl_settings)),
    "amplifier_bandwidth": Effect("amplifier_bandwidth", "high-frequency attenuation and phase lag of a "
                                  "first-order pole (edges rounded)", _bw_settings, _dd_reg("amplifier_bandwidth"),
                                  _dd_term("amplifier_bandwidth", "hz", lambda ctx, x: float(x)), _bw_desc,
                                  group="drive_dynamics", refine=_geo_refine(_bw_settings)),
    "sensor_nonlinearity": _with_intercept(Effect("sensor_nonlinearity", "static function of the measured displacement",
                                  _one, _sn_reg, _sn_term, _sn_desc)),
    "saturation": Effect("saturation", "residual only beyond a drive threshold, growing with the excess",
                         _sat_settings, _sat_reg, _sat_term, _sat_desc, refine=_sat_refine),
    "asymmetric_hysteresis": _with_intercept(Effect("asymmetric_hysteresis", "even function of the drive (loop not "
                                    "point-symmetric)", _one, _ah_reg, _ah_term, _ah_desc)),
}
