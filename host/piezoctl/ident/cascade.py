"""Model kind ``cascade``: rate-independent hysteresis (EUPI) followed by linear dynamics.

    y = G(s)[ H[u] ],   H: EUPI (:mod:`piezoctl.ident.eupi`), G: continuous transfer function

Identification (the paper's procedure)

1. Split the recordings into quasi-static and dynamic ones: a recording is
   quasi-static if the power-weighted mean frequency (spectral centroid) of its
   detrended drive u is below ``--cascade-static-hz`` (default 2 Hz), dynamic
   otherwise. ``--cascade-static`` lists the quasi-static files by index instead
   (0-based, in ``--data`` order). With only one kind of recording the fit is
   refused, unless ``--cascade-fallback``: then every recording serves both
   steps (the hysteresis from all data, the dynamics from the response of all
   data to the hysteresis output) and the joint refinement separates them.
2. Fit the EUPI hysteresis H on the quasi-static recordings (the ``eupi`` kind
   with its default options).
3. For each dynamic recording (in the paper: the stage driven by the EUPI
   inverse of a chirp, so that H[u] is close to the chirp), compute the
   hysteresis output w = H[u] and estimate the FRF from w to y
   (:func:`piezoctl.ident.tf.frf_from_time`, Welch, lines with coherence >=
   0.8 between ``--cascade-fmin`` and ``--cascade-fmax``). The FRFs of all
   dynamic files are pooled (sorted by frequency; equal frequencies averaged).
4. Fit G of order ``--cascade-order`` by ``--cascade-method`` (``pso-wcls``
   default, or ``wcls``) (:mod:`piezoctl.ident.tf`).
5. Joint refinement (``--cascade-refine`` function evaluations, 0 = off),
   on the time-domain data of all recordings, by variable projection in
   ``--cascade-refine-rounds`` rounds (default 2): (a) with G fixed, the
   output is linear in the EUPI weights (G is linear: G[sum_k w_k x_k] =
   sum_k w_k G[x_k]), so the weights a0, b, d, p and the offset are refitted
   by bounded least squares (a0 > 0, b, d >= 0) on the operator outputs
   filtered through G; (b) with H fixed, ``scipy.optimize.least_squares``
   refines G's coefficients (scaled by the FRF's top frequency) together with
   an affine correction ``c1 H[u] + c0``. The small-gain k_ex of the refitted
   EUPI is chosen again. A round is kept only if G stays stable and the
   residual goes down.

``simulate`` runs H, then G discretized with a first-order hold at the
recording's sample period (:func:`piezoctl.ident.tf.simulate_tf`), starting at
the equilibrium of the first sample.

Parameters: ``hysteresis`` (the eupi parameters), ``num``, ``den`` [descending
powers of s, den[0] = 1], ``poles`` [[re, im] rad/s], ``te``, ``c1``, ``c0``
[um], ``static_files``, ``dynamic_files`` (indices), ``frf`` (f_hz, mag,
phase_deg of the pooled estimate).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from . import eupi as eupi_kind
from . import tf
from .common import IdentError, Options

KIND = "cascade"
DESCRIPTION = "EUPI hysteresis followed by linear dynamics fitted by WCLS / PSO-WCLS"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "split_recordings",
           "spectral_centroid"]

DEFAULTS = {"order": 2, "num_order": None, "method": "pso-wcls", "static_hz": 2.0, "static": None,
            "fmin": None, "fmax": None, "refine": 50, "refine_rounds": 2, "seed": 0, "fallback": False,
            "joint": False, "creep": "auto", "cv_folds": 4, "u_before": None}


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--cascade-``)."""
    parser.add_argument("--cascade-order", type=int, default=2, help="order n of the dynamics (default 2)")
    parser.add_argument("--cascade-num-order", type=int, default=None,
                        help="numerator order (default: n)")
    parser.add_argument("--cascade-method", choices=("wcls", "pso-wcls"), default="pso-wcls")
    parser.add_argument("--cascade-static-hz", type=float, default=2.0,
                        help="drive spectral centroid [Hz] below which a file is quasi-static (default 2)")
    parser.add_argument("--cascade-static", type=int, nargs="+", default=None, metavar="I",
                        help="indices (0-based) of the quasi-static files, instead of the spectrum rule")
    parser.add_argument("--cascade-fmin", type=float, default=None, help="lowest FRF frequency [Hz]")
    parser.add_argument("--cascade-fmax", type=float, default=None, help="highest FRF frequency [Hz]")
    parser.add_argument("--cascade-refine", type=int, default=50,
                        help="function evaluations of the joint time-domain refinement (0: off)")
    parser.add_argument("--cascade-refine-rounds", type=int, default=2,
                        help="rounds of weights-then-dynamics refinement (default 2)")
    parser.add_argument("--cascade-fallback", action="store_true",
                        help="when the data has only quasi-static or only dynamic recordings, use every "
                             "recording for both steps (the joint refinement then does the separating)")
    parser.add_argument("--cascade-seed", type=int, default=0, help="PSO seed")
    parser.add_argument("--cascade-joint", action="store_true",
                        help="identify hysteresis weights, creep, a second-order mode and a delay jointly "
                             "from the time-domain data of every recording (variable projection), in place "
                             "of the quasi-static / FRF steps: for runs that are not a quasi-static + chirp pair, "
                             "such as sweeps (docs/identification.md)")
    parser.add_argument("--cascade-creep", default="auto", choices=("auto", "0", "1", "2", "3", "4"),
                        help="with --cascade-joint: creep lags, time constants 0.01 5^k s (k < n); auto "
                             "(default): the count with the lowest cross-validated NRMSE inside the data")
    parser.add_argument("--cascade-cv-folds", type=int, default=4, metavar="K",
                        help="with --cascade-joint: folds of the cross-validation, drive periods dealt "
                             "round-robin (default 4)")
    parser.add_argument("--cascade-u-before", type=float, default=None, metavar="V",
                        help="with --cascade-joint: drive [V] held before each recording's first sample "
                             "(the model then predicts the start-up step; default: none, the model starts "
                             "at rest at the first sample)")


def _opt(options, name):
    v = options.get(f"cascade_{name}") if options is not None else None
    return DEFAULTS[name] if v is None else v


def spectral_centroid(t, u) -> float:
    """Power-weighted mean frequency [Hz] of the detrended drive ``u`` sampled at ``t`` [s]."""
    u = np.asarray(u, dtype=float)
    t = np.asarray(t, dtype=float)
    if u.size < 4:
        return 0.0
    uu = u - np.polyval(np.polyfit(t - t[0], u, 1), t - t[0]) if np.ptp(u) > 0 else u * 0
    p = np.abs(np.fft.rfft(uu * np.hanning(u.size))) ** 2
    f = np.fft.rfftfreq(u.size, float(np.mean(np.diff(t))))
    return float(np.sum(f * p) / np.sum(p)) if np.sum(p) > 0 else 0.0


def split_recordings(recordings, options=None) -> tuple[list[int], list[int]]:
    """Indices (quasi-static, dynamic) of the recordings (see the module notes)."""
    idx = _opt(options, "static")
    if idx is not None:
        static = sorted(set(int(i) for i in idx))
        if any(i < 0 or i >= len(recordings) for i in static):
            raise IdentError(f"--cascade-static {idx}: indices must be in 0..{len(recordings) - 1}")
    else:
        lim = float(_opt(options, "static_hz"))
        static = [i for i, r in enumerate(recordings) if spectral_centroid(r.t, r.u) < lim]
    dynamic = [i for i in range(len(recordings)) if i not in static]
    if not static or not dynamic:
        if not _opt(options, "fallback"):
            raise IdentError(f"cascade needs quasi-static and dynamic recordings (got {len(static)} "
                             f"quasi-static, {len(dynamic)} dynamic; see --cascade-static-hz / --cascade-static, "
                             f"or --cascade-fallback)")
        # one kind of recording only: every recording serves both steps
        static = dynamic = list(range(len(recordings)))
    return static, dynamic


def _pool(frfs) -> tf.FRF:
    f = np.concatenate([x.f_hz for x in frfs])
    h = np.concatenate([x.h for x in frfs])
    uf, inv = np.unique(f, return_inverse=True)
    hh = np.array([h[inv == k].mean() for k in range(uf.size)])
    return tf.FRF(uf, np.abs(hh), np.rad2deg(np.unwrap(np.angle(hh))))


def _hyst_opts(options) -> Options:
    o = Options({k: v for k, v in (options or {}).items() if not k.startswith("cascade_")})
    o.setdefault("offset", "shared")
    o.setdefault("max_fit_rows", 200_000)
    o.setdefault("u_range", None)
    return o


def fit(recordings, options) -> dict:
    """Fit the cascade (see the module notes).

    Parameters
    ----------
    recordings : sequence of Recording
        Quasi-static and dynamic recordings (``t`` [s], ``u`` [V], ``y`` [um]).
    options : Options or mapping
        ``cascade_*`` options and the common ones.

    Returns
    -------
    dict
        Parameters (see the module docstring).
    """
    if _opt(options, "joint"):
        from .cascade_joint import fit_joint
        return fit_joint(recordings, options)
    given = [name for name, key in (("--cascade-creep", "creep"), ("--cascade-cv-folds", "cv_folds"),
                                    ("--cascade-u-before", "u_before")) if _opt(options, key) != DEFAULTS[key]]
    if given:
        raise IdentError(f"{', '.join(given)}: only with --cascade-joint")
    static, dynamic = split_recordings(recordings, options)
    hp = eupi_kind.fit([recordings[i] for i in static], _hyst_opts(options))
    frfs = []
    for i in dynamic:
        r = recordings[i]
        w = eupi_kind.simulate(hp, r.t, r.u)
        try:
            frfs.append(tf.frf_from_time(r.t, w, r.y, fmin=_opt(options, "fmin"), fmax=_opt(options, "fmax"),
                                         coherence_min=0.8))
        except ValueError as exc:
            raise IdentError(f"cascade: recording {i}: {exc}") from None
    frf = _pool(frfs)
    order = int(_opt(options, "order"))
    nb = _opt(options, "num_order")
    try:
        res = tf.fit_tf(frf, order, _opt(options, "method"), nb,
                        **({"seed": int(_opt(options, "seed"))} if _opt(options, "method") == "pso-wcls" else {}))
    except ValueError as exc:
        raise IdentError(f"cascade: fitting the dynamics failed: {exc}") from None
    params = {"hysteresis": hp, "num": res.num, "den": res.den, "te": res.te, "method": res.method,
              "c1": 1.0, "c0": 0.0, "static_files": static, "dynamic_files": dynamic,
              "frf": {"f_hz": frf.f_hz, "mag": frf.mag, "phase_deg": frf.phase_deg}}
    n_eval = int(_opt(options, "refine"))
    if n_eval > 0:
        first = None
        xs = [_operator_columns(hp, r.u) for r in recordings]  # weight-free: computed once
        for _ in range(max(1, int(_opt(options, "refine_rounds")))):
            step = refine_weights(params, recordings, xs)
            params.update(step)
            ws = [_hysteresis_output(params["hysteresis"], x) for x in xs]
            step2 = refine(params, recordings, n_eval, w0=float(frf.w.max()), ws=ws)
            params.update(step2)
            first = first if first is not None else step.get("refine_weights_cost", step2["refine_cost"])[0]
            if step2["refine_cost"][1] >= step2["refine_cost"][0] and "refine_weights_cost" not in step:
                break
        params["refine_cost"] = [first, params["refine_cost"][1]]
    params["num"] = [float(v) for v in params["num"]]
    params["den"] = [float(v) for v in params["den"]]
    params["poles"] = [[float(p.real), float(p.imag)] for p in tf.poles_of(params["den"])]
    params["stable"] = tf.is_stable(params["den"])
    return params


def refine(params: dict, recordings, max_nfev: int, w0: float, ws=None) -> dict:
    """Joint time-domain refinement of G's coefficients and the affine hysteresis correction.

    Parameters
    ----------
    params : dict
        A cascade parameter set (``num``, ``den``, ``c1``, ``c0``, ``hysteresis``).
    recordings : sequence of Recording
        Data (all of them).
    max_nfev : int
        Function evaluations of ``least_squares``.
    w0 : float
        Frequency scale [rad/s]: coefficients are optimized as ``b_k / w0^(n-k)``.
    ws : list of ndarray, optional
        The hysteresis output H[u] [um] of each recording, if already known.

    Returns
    -------
    dict
        ``num``, ``den``, ``c1``, ``c0`` and ``refine_cost`` ([before, after] sum of
        squared errors [um^2]); the input values if refinement did not help.
    """
    num, den = np.asarray(params["num"], float), np.asarray(params["den"], float)
    n, nb = den.size - 1, num.size - 1
    if ws is None:
        ws = [eupi_kind.simulate(params["hysteresis"], r.t, r.u) for r in recordings]
    sc_b = w0 ** (n - np.arange(nb, -1, -1.0))
    sc_a = w0 ** (n - np.arange(n - 1, -1, -1.0))

    def unpack(z):
        return z[: nb + 1] * sc_b, np.concatenate(([1.0], z[nb + 1: nb + 1 + n] * sc_a)), z[-2], z[-1]

    def resid(z):
        b, a, c1, c0 = unpack(z)
        if not tf.is_stable(a):
            return np.full(sum(len(r.y) for r in recordings), 1e3)
        return np.concatenate([tf.simulate_tf(b, a, r.t, c1 * w + c0) - r.y for r, w in zip(recordings, ws)])

    z0 = np.concatenate([num / sc_b, den[1:] / sc_a, [params["c1"], params["c0"]]])
    cost0 = float(np.sum(resid(z0) ** 2))
    sol = optimize.least_squares(resid, z0, x_scale="jac", max_nfev=max_nfev)
    b, a, c1, c0 = unpack(sol.x)
    cost1 = float(np.sum(resid(sol.x) ** 2))
    if cost1 < cost0 and tf.is_stable(a):
        return {"num": b, "den": a, "c1": float(c1), "c0": float(c0), "refine_cost": [cost0, cost1]}
    return {"refine_cost": [cost0, cost0]}


def _operator_columns(hp: dict, u) -> np.ndarray:
    """The EUPI kind's regressor columns for drive u [V]: v, CPI plays, UPI plays, v^2..v^Np."""
    from ..models.play import play_outputs
    from .common import normalize
    v = normalize(np.asarray(u, float), hp["u_min"], hp["u_max"])
    cols = [v[:, None]]
    r_cpi = np.asarray(hp["r_cpi"], float)
    if r_cpi.size:
        cols.append(play_outputs(v, r_cpi))
    r_upi, a_upi = np.asarray(hp["r_upi"], float), np.asarray(hp["a_upi"], float)
    if r_upi.size and a_upi.size:
        cols.append(play_outputs(v, np.repeat(r_upi, a_upi.size), np.tile(a_upi, r_upi.size)))
    npoly = len(hp["p"]) + 1
    if npoly >= 2:
        cols.append(v[:, None] ** np.arange(2, npoly + 1)[None, :])
    return np.hstack(cols)


def _hysteresis_output(hp: dict, x: np.ndarray) -> np.ndarray:
    """H[u] [um] from the operator columns of u: y_mid + y_half (X theta + p0)."""
    d = np.asarray(hp["d"], float).ravel()
    theta = np.concatenate([[hp["a0"]], np.asarray(hp["b"], float), d, np.asarray(hp["p"], float)])
    return float(hp["y_mid"]) + float(hp["y_half"]) * (x @ theta + float(hp["p0"]))


def refine_weights(params: dict, recordings, xs=None) -> dict:
    """Refit the EUPI weights with the dynamics G fixed (variable projection, step a).

    ``y = G[c1 (y_mid + y_half (X theta + p0)) + c0]`` is linear in ``theta``
    and the offset: the columns of X are filtered through G and the weights
    solved by bounded least squares (a0 >= A0_MIN, b, d >= 0, p free). The
    affine correction is folded into the refitted weights (c1 = 1, c0 = 0).

    ``xs``: the operator columns of each recording (:func:`_operator_columns`),
    if already computed.

    Returns
    -------
    dict
        ``hysteresis`` (refitted, k_ex chosen again), ``c1``, ``c0`` and
        ``refine_weights_cost`` ([before, after] [um^2]); empty if it did not help.
    """
    hp = dict(params["hysteresis"])
    num, den = params["num"], params["den"]
    if xs is None:
        xs = [_operator_columns(hp, r.u) for r in recordings]
    c1, c0 = float(params.get("c1", 1.0)), float(params.get("c0", 0.0))
    num_den = (num, den)

    def cost(h, a1, a0_):
        return float(sum(np.sum((tf.simulate_tf(*num_den, r.t, a1 * _hysteresis_output(h, x) + a0_) - r.y) ** 2)
                         for r, x in zip(recordings, xs)))

    gx, ys = [], []
    for r, X in zip(recordings, xs):
        cols = [tf.simulate_tf(num, den, r.t, X[:, k]) for k in range(X.shape[1])]
        cols.append(tf.simulate_tf(num, den, r.t, np.ones_like(r.t)))
        gx.append(np.column_stack(cols))
        ys.append(r.y)
    A, y = np.vstack(gx), np.concatenate(ys)
    n_cpi, n_u = len(hp["r_cpi"]), len(hp["r_upi"]) * len(hp["a_upi"])
    lo = np.concatenate([[eupi_kind.A0_MIN], np.zeros(n_cpi + n_u), np.full(A.shape[1] - 1 - n_cpi - n_u, -np.inf)])
    hi = np.full(A.shape[1], np.inf)
    cost0 = cost(hp, c1, c0)
    # output units: y = (X theta' ) with theta' = y_half theta; the last column is the constant
    sol = optimize.lsq_linear(A, y, bounds=(lo, hi), method="bvls")
    new = _eupi_with_weights(hp, sol.x[:-1], float(sol.x[-1]))
    cost1 = cost(new, 1.0, 0.0)
    if cost1 < cost0:
        return {"hysteresis": new, "c1": 1.0, "c0": 0.0, "refine_weights_cost": [cost0, cost1]}
    return {}


def _eupi_with_weights(hp: dict, th_um, offset_um: float) -> dict:
    """EUPI parameters ``hp`` with the weights of its operator columns replaced.

    ``th_um``: weights [um per operator output] of :func:`_operator_columns`'
    columns (a0, b, d row-major, p), ``offset_um`` [um]; converted to the
    normalized units (divided by ``y_half``), signs clipped to the EUPI's
    bounds, ``k_ex`` chosen again for the margin 0.05.
    """
    from ..models import eupi as eupiref
    th = np.asarray(th_um, float)
    n_cpi, n_u = len(hp["r_cpi"]), len(hp["r_upi"]) * len(hp["a_upi"])
    yh = float(hp["y_half"])
    new = dict(hp)
    new["a0"] = float(max(th[0] / yh, eupi_kind.A0_MIN))
    new["b"] = np.maximum(th[1:1 + n_cpi] / yh, 0.0)
    d = np.maximum(th[1 + n_cpi:1 + n_cpi + n_u] / yh, 0.0)
    new["d"] = d.reshape(len(hp["r_upi"]), len(hp["a_upi"])) if n_u else np.zeros((0, 0))
    new["p"] = th[1 + n_cpi + n_u:] / yh
    new["p0"] = float((float(offset_um) - float(hp["y_mid"])) / yh)
    base = eupi_kind.to_params({**new, "k_ex": 0.0})
    new["margin_at_kex0"] = eupiref.small_gain_margin(base, -1.0, 1.0)
    try:
        kex = eupiref.choose_kex(base, -1.0, 1.0, margin=0.05)
        new["k_ex"], new["invertible"] = kex, True
        new["small_gain_margin"] = eupiref.small_gain_margin(eupiref.apply_kex(base, kex), -1.0, 1.0)
    except ValueError:
        new["k_ex"], new["invertible"], new["small_gain_margin"] = 0.0, False, new["margin_at_kex0"]
    return new


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V]: EUPI, then the discretized dynamics (``u2`` unused).

    A model from ``--cascade-joint`` (``method`` "joint") also has creep lags,
    a delay and possibly the drive before the first sample
    (:func:`piezoctl.ident.cascade_joint.simulate_joint`).
    """
    if params.get("method") == "joint":
        from .cascade_joint import simulate_joint
        return simulate_joint(params, t, u)
    w = eupi_kind.simulate(params["hysteresis"], t, u)
    w = float(params.get("c1", 1.0)) * w + float(params.get("c0", 0.0))
    return tf.simulate_tf(params["num"], params["den"], t, w)
