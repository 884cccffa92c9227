"""Joint identification of the ``cascade`` kind (``--cascade-joint``): hysteresis, creep, mode and delay.

The model, with ``v`` the drive normalized to [-1, 1] and all terms in um::

    y(t) = G[ H[v] + sum_i g_i C_i[v] ](t - tau_d)

- ``H``: the EUPI hysteresis of :mod:`piezoctl.ident.eupi` (CPI + UPI plays,
  polynomial, offset), its thresholds and tilts chosen by the ``eupi`` fit;
- ``C_i = 1 / (1 + s T_i)``: creep lags of the drive, ``T_i = 0.01 * 5**i`` s
  (``i < n``: 0.01, 0.05, 0.25, 1.25 s), gains ``g_i`` [um per FS];
- ``G = wn^2 / (s^2 + 2 zeta wn s + wn^2)``: one mode, unit static gain;
- ``tau_d``: a delay [s], fractional samples by linear interpolation.

Why: fitted in the time domain, every part of a recording weighs in at
once: a triangle sweep's harmonics (20 Hz: 20, 40, 60, ... Hz) carry the
hysteresis and the creep, and a step in the data (the valve recordings start
with the drive switched on from 0 V, ``--cascade-u-before 0``) rings at the
mode. On the valve the harmonics alone leave the 730 Hz mode undetermined;
the step places it (docs/identification.md). The FRF route of the plain
``cascade`` uses neither: coherence lines from one triangle do not determine
G above its harmonics.

Identification (variable projection): for fixed ``(f_n, zeta, tau_d)`` the
output is linear in the hysteresis weights, the creep gains and the offset
(G and the delay are linear, and G passes a constant unchanged), so those are
solved by least squares on the operator columns filtered through G, and
``scipy.optimize.least_squares`` minimizes the remaining residual over
``(log f_n, zeta, tau_d)``, started from the best of a grid (12 frequencies
from 20 Hz to 0.4 fs, zeta 0.05 and 0.3). The count of creep lags ``n`` (0..4)
is chosen by K-fold cross-validation inside the fit data
(``--cascade-cv-folds``, default 4): the drive's periods (its strongest
spectral line) are dealt round-robin to the folds; for each ``n`` the
dynamics are fitted on all rows, then the linear weights on all folds but
one and scored on the one left out; the lowest pooled NRMSE wins. A final
bounded solve keeps the EUPI weights' signs (``a0 >= A0_MIN``, ``b, d >=
0``; the creep gains are free) and ``k_ex`` is chosen as in ``eupi``.

Start: with ``u_before`` the drive is taken as held at ``u_before`` forever
before the first sample (plays relaxed then moved to it, every lag at its
equilibrium); without, everything starts at rest at the first sample.

Parameters added to the cascade's (``method`` = ``"joint"``): ``creep``
{``tau_s`` [s], ``gain_um`` [um per FS]}, ``delay_s`` [s], ``u_before`` [V]
or null, ``mode_hz``, ``zeta``, ``cv`` {``folds``, ``creep_counts``,
``nrmse``, ``chosen``}; ``num``, ``den`` are the mode's.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize, signal

from . import eupi as eupi_kind
from . import tf
from .common import IdentError, check_positive_int, fit_stride, normalize, solve_linear

__all__ = ["fit_joint", "simulate_joint", "creep_taus", "mode_tf", "lti_columns", "delay_columns",
           "period_folds", "fundamental_hz", "CREEP_TAU0_S", "CREEP_RATIO", "MAX_CREEP"]

CREEP_TAU0_S = 0.01   # first creep time constant [s]
CREEP_RATIO = 5.0     # ratio between successive creep time constants
MAX_CREEP = 4         # creep lags offered to the cross-validation
MAX_DELAY_SAMPLES = 20.0


def creep_taus(n: int) -> np.ndarray:
    """The first ``n`` creep time constants [s]: ``0.01 * 5**i``."""
    return CREEP_TAU0_S * CREEP_RATIO ** np.arange(int(n), dtype=float)


def mode_tf(f_hz: float, zeta: float) -> tuple[list, list]:
    """``(num, den)`` of ``wn^2 / (s^2 + 2 zeta wn s + wn^2)``, ``wn = 2 pi f_hz`` [rad/s]."""
    wn = 2.0 * np.pi * float(f_hz)
    return [wn * wn], [1.0, 2.0 * float(zeta) * wn, wn * wn]


def lti_columns(num, den, dt: float, X: np.ndarray) -> np.ndarray:
    """Every column of ``X`` through ``num/den`` (first-order hold at ``dt`` [s]), started at rest.

    The same difference equation and start as :func:`piezoctl.ident.tf.simulate_tf`
    (equilibrium for the first sample), for all columns at once.
    """
    X = np.asarray(X, dtype=np.float64)
    ad, bd, cd, dd = tf.discretize(num, den, dt)
    b, a = signal.ss2tf(ad, bd, cd, dd)
    b = np.atleast_1d(np.asarray(b, dtype=float)[0])
    zi = signal.lfilter_zi(b, a)
    return signal.lfilter(b, a, X, axis=0, zi=zi[:, None] * X[:1, :])[0]


def delay_columns(Y: np.ndarray, d: float) -> np.ndarray:
    """Delay the rows of ``Y`` by ``d >= 0`` samples (linear interpolation, first row held before)."""
    k = int(np.floor(d))
    f = float(d) - k
    T = Y.shape[0]
    idx0 = np.clip(np.arange(T) - k, 0, T - 1)
    idx1 = np.clip(np.arange(T) - k - 1, 0, T - 1)
    return (1.0 - f) * Y[idx0] + f * Y[idx1]


def fundamental_hz(t, u) -> float:
    """Frequency [Hz] of the strongest spectral line of the drive's rate (0 for a constant drive).

    For a triangle the rate is a square wave at the fundamental; a held start
    adds little there.
    """
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    du = np.diff(u, prepend=u[0])
    p = np.abs(np.fft.rfft(du * np.hanning(u.size))) ** 2
    f = np.fft.rfftfreq(u.size, float(np.median(np.diff(t))))
    p[0] = 0.0
    return float(f[int(np.argmax(p))]) if np.any(p > 0) else 0.0


def period_folds(t, u, k: int) -> np.ndarray:
    """Fold index (0..k-1) of every sample: the drive's periods dealt round-robin.

    The period is that of the strongest spectral line of the drive's rate
    (for a triangle, a square wave at the fundamental; a held start adds
    little there). A drive with fewer than ``k`` periods (or constant) is cut
    into ``k`` contiguous blocks instead.
    """
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    span = float(t[-1] - t[0])
    f0 = fundamental_hz(t, u)
    if f0 * span < k:
        return np.minimum((np.arange(u.size) * k) // u.size, k - 1)
    return (np.floor((t - t[0]) * f0).astype(int)) % int(k)


def _extend(u, u_before):
    u = np.asarray(u, dtype=np.float64)
    if u_before is None:
        return u, 0
    return np.concatenate(([float(u_before)], u)), 1


def _creep_columns(v_ext: np.ndarray, taus, dt: float) -> np.ndarray:
    if len(taus) == 0:
        return np.zeros((v_ext.size, 0))
    return np.column_stack([lti_columns([1.0], [float(T), 1.0], dt, v_ext[:, None])[:, 0] for T in taus])


class _Problem:
    """The data of a joint fit: per recording the unfiltered design columns and the fit rows."""

    def __init__(self, recordings, hp, u_before, max_rows, folds):
        from .cascade import _operator_columns
        self.y_range = max(float(np.max(r.y)) for r in recordings) - min(float(np.min(r.y)) for r in recordings)
        self.dts, self.X, self.C, self.rows, self.ys, self.folds = [], [], [], [], [], []
        stride = fit_stride(sum(len(r.t) for r in recordings), max_rows)
        taus = creep_taus(MAX_CREEP)
        for r in recordings:
            dt = float(np.median(np.diff(r.t)))
            u_ext, n0 = _extend(r.u, u_before)
            self.dts.append(dt)
            self.X.append(_operator_columns(hp, u_ext))
            self.C.append(_creep_columns(normalize(u_ext, hp["u_min"], hp["u_max"]), taus, dt))
            idx = np.arange(0, len(r.t), stride)
            self.rows.append(idx + n0)           # rows of the extended signals
            self.ys.append(np.asarray(r.y, float)[idx])
            self.folds.append(period_folds(r.t, r.u, folds)[idx])
        self.P = self.X[0].shape[1]

    def filtered(self, z, n):
        """Design matrices [operators, creep lags, 1] through the mode and delay, at the fit rows."""
        num, den = mode_tf(np.exp(z[0]), z[1])
        out = []
        for X, C, rows, dt in zip(self.X, self.C, self.rows, self.dts):
            D = np.hstack([X, C[:, :n], np.ones((X.shape[0], 1))])
            out.append(delay_columns(lti_columns(num, den, dt, D), z[2])[rows])
        return out

    def residual(self, z, n):
        A = np.vstack(self.filtered(z, n))
        y = np.concatenate(self.ys)
        th = np.linalg.lstsq(A, y, rcond=None)[0]
        return A @ th - y

    def cv_nrmse(self, z, n):
        """Pooled NRMSE of the linear weights fitted on all folds but one, scored on that one."""
        A = np.vstack(self.filtered(z, n))
        y = np.concatenate(self.ys)
        fold = np.concatenate(self.folds)
        sse, cnt = 0.0, 0
        for k in np.unique(fold):
            tr, te = fold != k, fold == k
            th = np.linalg.lstsq(A[tr], y[tr], rcond=None)[0]
            sse += float(np.sum((A[te] @ th - y[te]) ** 2))
            cnt += int(te.sum())
        return float(np.sqrt(sse / max(cnt, 1)) / self.y_range)


def _fit_dynamics(prob: _Problem, n: int, z0, dt: float, max_nfev: int = 60):
    lo = [np.log(1.0), 0.002, 0.0]
    hi = [np.log(0.45 / dt), 5.0, MAX_DELAY_SAMPLES]
    z0 = np.clip(z0, np.add(lo, 1e-9), np.subtract(hi, 1e-9))
    sol = optimize.least_squares(lambda z: prob.residual(z, n), z0, bounds=(lo, hi),
                                 x_scale=[0.1, 0.01, 0.5], max_nfev=max_nfev)
    return sol.x, float(np.sum(sol.fun ** 2))


def fit_joint(recordings, options) -> dict:
    """Fit the cascade jointly (see the module notes).

    Parameters
    ----------
    recordings : sequence of Recording
        Data (``t`` [s], ``u`` [V], ``y`` [um]); every one enters every step.
    options : Options or mapping
        ``cascade_order`` (must be 2), ``cascade_creep`` ("auto" or 0..4),
        ``cascade_cv_folds``, ``cascade_u_before`` [V] and the common ones.

    Returns
    -------
    dict
        Cascade parameters with ``method`` "joint" (module docstring).
    """
    from .cascade import _eupi_with_weights, _hyst_opts, _opt
    if int(_opt(options, "order")) != 2 or _opt(options, "num_order") not in (None, 0):
        raise IdentError("--cascade-joint fits one second-order mode: --cascade-order 2 and no "
                         "--cascade-num-order")
    if options.get("offset", "shared") != "shared":
        raise IdentError("--cascade-joint fits one offset shared by all files (no --offset per-file)")
    k = check_positive_int("--cascade-cv-folds", _opt(options, "cv_folds"), 2)
    creep = str(_opt(options, "creep"))
    if creep != "auto" and creep not in {str(i) for i in range(MAX_CREEP + 1)}:
        raise IdentError(f"--cascade-creep {creep}: must be auto or 0..{MAX_CREEP}")
    u_before = _opt(options, "u_before")
    if u_before is not None and not np.isfinite(float(u_before)):
        raise IdentError(f"--cascade-u-before {u_before}: must be a finite voltage")
    dts = [float(np.median(np.diff(r.t))) for r in recordings]
    if max(dts) / min(dts) > 1.01:
        raise IdentError("--cascade-joint needs data files of one sample rate")
    dt = dts[0]
    hp = eupi_kind.fit(recordings, _hyst_opts(options))     # thresholds, tilts, first weights
    prob = _Problem(recordings, hp, u_before, int(options.get("max_fit_rows", 200_000)), k)

    # start: the best of a grid of modes, no creep, no delay
    grid = [(np.log(f), zeta, 0.0) for f in np.geomspace(20.0, 0.4 / dt, 12) for zeta in (0.05, 0.3)]
    z = np.array(min(grid, key=lambda g: float(np.sum(prob.residual(np.array(g), 0) ** 2))))
    counts = list(range(MAX_CREEP + 1)) if creep == "auto" else [int(creep)]
    fits = {}
    for n in counts:        # warm start from the previous count
        z, cost = _fit_dynamics(prob, n, z, dt)
        fits[n] = (z.copy(), cost, prob.cv_nrmse(z, n))
    n = min(counts, key=lambda c: fits[c][2])
    z = fits[n][0]

    # final weights: bounded (EUPI signs), on the operator and creep columns filtered through G
    feats = [A[:, :-1] for A in _all_rows(prob, z, n)]
    n_cpi, n_u = len(hp["r_cpi"]), len(hp["r_upi"]) * len(hp["a_upi"])
    y_half = float(hp["y_half"])
    lower = np.concatenate([[eupi_kind.A0_MIN * y_half], np.zeros(n_cpi + n_u),
                            np.full(prob.P - 1 - n_cpi - n_u + n, -np.inf)])
    res = solve_linear(feats, [r.y for r in recordings], lower=lower, offset="shared",
                       max_rows=int(options.get("max_fit_rows", 200_000)))
    th = res.coef
    new_hp = _eupi_with_weights(hp, th[:prob.P], res.offset)
    f_hz, zeta, d = float(np.exp(z[0])), float(z[1]), float(z[2])
    num, den = mode_tf(f_hz, zeta)
    return {"hysteresis": new_hp, "num": num, "den": den, "te": None, "method": "joint",
            "c1": 1.0, "c0": 0.0, "static_files": list(range(len(recordings))),
            "dynamic_files": list(range(len(recordings))),
            "mode_hz": f_hz, "zeta": zeta, "delay_s": d * dt,
            "creep": {"tau_s": creep_taus(n).tolist(), "gain_um": [float(g) for g in th[prob.P:prob.P + n]]},
            "u_before": None if u_before is None else float(u_before),
            "cv": {"folds": k, "creep_counts": counts, "nrmse": [fits[c][2] for c in counts], "chosen": n},
            "fit_cost_um2": fits[n][1]}


def _all_rows(prob: _Problem, z, n):
    """Filtered design matrices at every sample (not only the fit rows), the extension dropped."""
    num, den = mode_tf(np.exp(z[0]), z[1])
    out = []
    for X, C, rows, dt in zip(prob.X, prob.C, prob.rows, prob.dts):
        D = np.hstack([X, C[:, :n], np.ones((X.shape[0], 1))])
        n0 = int(rows[0])
        out.append(delay_columns(lti_columns(num, den, dt, D), z[2])[n0:])
    return out


def _check(params: dict) -> tuple[np.ndarray, np.ndarray, float, float | None]:
    creep = params.get("creep") or {"tau_s": [], "gain_um": []}
    try:
        taus = np.asarray(creep.get("tau_s", []), dtype=float).ravel()
        gains = np.asarray(creep.get("gain_um", []), dtype=float).ravel()
        delay = float(params.get("delay_s", 0.0))
        ub = params.get("u_before")
        ub = None if ub is None else float(ub)
    except (TypeError, ValueError, AttributeError):
        raise IdentError("cascade model: creep, delay_s, u_before must be numbers") from None
    if taus.size != gains.size or taus.size > 16 or np.any(~np.isfinite(taus)) or np.any(taus <= 0) \
            or np.any(~np.isfinite(gains)):
        raise IdentError("cascade model: creep.tau_s (> 0) and creep.gain_um must be lists of one length "
                         "(at most 16), finite")
    if not (np.isfinite(delay) and 0.0 <= delay <= 1.0):
        raise IdentError(f"cascade model: delay_s {delay}: must be in [0, 1] s")
    if ub is not None and not np.isfinite(ub):
        raise IdentError("cascade model: u_before must be finite or null")
    if len(params.get("den", [])) != 3:
        raise IdentError("cascade model (joint): den must be a second-order denominator")
    return taus, gains, delay, ub


def simulate_joint(params: dict, t, u) -> np.ndarray:
    """Output y [um] of a joint cascade for drive u [V] at uniform times t [s]."""
    from .cascade import _hysteresis_output, _operator_columns
    taus, gains, delay, ub = _check(params)
    t = np.asarray(t, dtype=np.float64)
    if t.size < 2:
        raise IdentError("cascade model: the input needs at least two samples")
    dt = float(np.median(np.diff(t)))
    hp = params["hysteresis"]
    u_ext, n0 = _extend(u, ub)
    w = _hysteresis_output(hp, _operator_columns(hp, u_ext))
    if taus.size:
        w = w + _creep_columns(normalize(u_ext, hp["u_min"], hp["u_max"]), taus, dt) @ gains
    y = delay_columns(lti_columns(params["num"], params["den"], dt, w[:, None]), delay / dt)[:, 0]
    return y[n0:]
