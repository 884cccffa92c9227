"""The diagnosis' base model: hysteresis plus linear dynamics fitted on calibration recordings.

H[u] = sum_i w_i P_ri(v) + c1 v + c2 v^2 + c3 v^3 + offset  (play operators P with
thresholds evenly spread up to 0.8, v the drive normalized over the calibration range;
ridge 1e-6 of the mean diagonal on unit-RMS columns, so that a barely moving wide play
cannot take a huge weight), followed by a discrete transfer function G of
unit static gain. The fit alternates two linear problems:

1. H with G = 1 on zero-phase low-passed (20 Hz) data (least squares over at most
   ``max_rows`` evenly strided samples);
2. G as an ARX model from H's output to y, refined for output error (least squares on
   the simulation error); order 0 (static), 2 or 4, a higher order kept only if it
   lowers the simulation error by 5 %;
3. H again, on features filtered by G; then G once more.

Everything runs at the recordings' sample rate (all calibration files must share it).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize
from scipy import signal as sig

from ..ident.common import IdentError
from ..ident.refined import bouc_wen_h, filt
from ..models.play import play_outputs

__all__ = ["fit_base", "fit_dynamics", "block_masks", "MAX_ROWS"]

MAX_ROWS = 200_000
ORDERS = (0, 2, 4)
LP_FIRST_HZ = 20.0
RIDGE = 1e-6
R_MAX = 0.8
BW_BETAS = tuple(float(x) for x in np.geomspace(0.5, 40.0, 7))   # a factor 2.1; Nelder-Mead refines
BW_GAMMA_RATIOS = (-0.6, -0.3, 0.0, 0.3, 0.6)


def block_masks(n: int, n_blocks: int) -> np.ndarray:
    """Block index (0..n_blocks-1) of each of n samples (contiguous, equal blocks)."""
    return np.minimum((np.arange(n) * n_blocks) // max(n, 1), n_blocks - 1)


def _features(v, r, v_rest) -> np.ndarray:
    P = play_outputs(v, r, y0=np.full(r.size, v_rest))
    return np.column_stack([P, v, v ** 2, v ** 3])


def _lstsq(X, y, ridge: float = 0.0):
    """Least squares on unit-RMS columns, with an optional ridge ``ridge * trace / k``."""
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    Xs = X / sc
    if ridge > 0:
        A = Xs.T @ Xs
        A[np.diag_indices_from(A)] += ridge * np.trace(A) / A.shape[0]
        th = np.linalg.solve(A, Xs.T @ y)
    else:
        th, *_ = np.linalg.lstsq(Xs, y, rcond=1e-10)
    return th / sc


def _arx(x_list, y_list, order, rows):
    """ARX fit y[k] + a1 y[k-1].. = b0 x[k] + .. + b_n x[k-n] + c; returns (b, a) or None."""
    if order == 0:
        return np.array([1.0]), np.array([1.0])
    Xs, ys = [], []
    for x, y in zip(x_list, y_list):
        n = y.size
        k = np.arange(order, n)
        if rows is not None and k.size > rows:
            k = k[:: int(np.ceil(k.size / rows))]
        cols = [-y[k - i] for i in range(1, order + 1)] + [x[k - i] for i in range(0, order + 1)]
        cols.append(np.ones(k.size))
        Xs.append(np.column_stack(cols))
        ys.append(y[k])
    th = _lstsq(np.vstack(Xs), np.concatenate(ys))
    a = np.concatenate([[1.0], th[:order]])
    b = th[order: 2 * order + 1]
    if np.any(np.abs(np.roots(a)) >= 0.9999) or abs(np.sum(b)) < 1e-12:
        return None
    b = b * (np.sum(a) / np.sum(b))  # unit static gain: H carries the gain
    return b, a


G_OUT_MAX = 3.0   # largest |G| allowed above twice the calibration's band (where it has no evidence)


def band_cps(xs, k0s) -> float:
    """Normalized frequency [cycles/sample] below which 99 % of the energy of the inputs' increments lies."""
    f_all, p_all = [], []
    for x, k0 in zip(xs, k0s):
        dx = np.diff(np.asarray(x, float)[k0:])
        if dx.size < 16:
            continue
        p_all.append(np.abs(np.fft.rfft(dx)) ** 2)
        f_all.append(np.fft.rfftfreq(dx.size, 1.0))
    if not f_all:
        return 0.5
    f, p = np.concatenate(f_all), np.concatenate(p_all)
    o = np.argsort(f)
    c = np.cumsum(p[o])
    return float(f[o][min(np.searchsorted(c, 0.99 * c[-1]), f.size - 1)])


def plausible(m, band) -> bool:
    """A dynamics model the calibration supports: |G| at most ``G_OUT_MAX`` above twice the calibration's
    band ``band`` [cycles/sample]. A slow calibration cannot identify fast dynamics, and an ARX fitted on it
    can put large gains at high frequency (a 20 Hz calibration gave |G| = 27 at Nyquist), which a step then
    excites."""
    if m is None:
        return False
    b, a = m
    if len(a) == 1 and len(b) == 1:
        return True
    f0 = min(2.0 * band, 0.5)
    if f0 >= 0.5:
        return True
    w = np.linspace(2 * np.pi * f0, np.pi, 256)
    _, hw = sig.freqz(b, a, worN=w)
    return bool(np.max(np.abs(hw)) <= G_OUT_MAX)


def _bw_features(v, beta, gamma, v_rest) -> np.ndarray:
    h = bouc_wen_h(v, beta, gamma, v_rest)
    return np.column_stack([h, v, v ** 2, v ** 3])


TREND_ORDER = 3   # per calibration recording, Legendre polynomials 1..TREND_ORDER of time enter the H fits


def _trends(ns, k0s) -> list:
    """Per recording, block columns of slow trends (Legendre P1..P3 of the settled time span; zero in the other
    recordings' blocks). They absorb slow drift in the calibration - a creep transient after power-up, a thermal
    settling - which would otherwise bend the hysteresis fit (a rising drift during a calibration loop of
    shrinking amplitude looks like amplitude-dependent shape); they are not part of the model."""
    out = []
    m = TREND_ORDER
    for i, (n, k0) in enumerate(zip(ns, k0s)):
        T = np.zeros((n, m * len(ns)))
        x = np.linspace(-1.0, 1.0, max(n - k0, 2))
        x = np.concatenate([np.full(k0, -1.0), x])[:n]
        T[:, i * m:(i + 1) * m] = np.polynomial.legendre.legvander(x, m)[:, 1:]
        out.append(T)
    return out


def _cv_h(Fs, ys, k0s, rows) -> float:
    """RMS error [um] of the static H fit, 2-fold over interleaved blocks (8 per recording)."""
    err, n = 0.0, 0
    Ts = _trends([y.size for y in ys], k0s)
    for f in (0, 1):
        tr = [np.column_stack([F, T, np.ones(F.shape[0])]) for F, T in zip(Fs, Ts)]
        m = [(block_masks(y.size, 8) % 2 == f) & (np.arange(y.size) >= k0) for y, k0 in zip(ys, k0s)]
        X = np.vstack([x[mm] for x, mm in zip(tr, m)])
        yy = np.concatenate([y[mm] for y, mm in zip(ys, m)])
        if X.shape[0] > rows:
            st = int(np.ceil(X.shape[0] / rows))
            X, yy = X[::st], yy[::st]
        th = _lstsq(X, yy, RIDGE)
        for x, y, mm, k0 in zip(tr, ys, m, k0s):
            t = (~mm) & (np.arange(y.size) >= k0)
            err += float(np.sum((x[t] @ th - y[t]) ** 2))
            n += int(np.sum(t))
    return float(np.sqrt(err / max(n, 1)))


def _sim_rmse(m, xs, ys, k0s) -> float:
    err = sum(float(np.sum((filt(m[0], m[1], x) - y)[k0:] ** 2)) for x, y, k0 in zip(xs, ys, k0s))
    return float(np.sqrt(err / sum(y.size - k0 for y, k0 in zip(ys, k0s))))


def _oe_refine(m, xs, ys, k0s, max_nfev: int = 30):
    """Output-error refinement of an ARX model (b, a): least squares on the simulation error."""
    b0, a0 = m
    n = a0.size - 1
    stride = max(1, int(np.ceil(sum(y.size for y in ys) / 100_000)))

    def unpack(z):
        a = np.concatenate([[1.0], z[:n]])
        b = z[n:]
        return b * (np.sum(a) / np.sum(b)), a

    def resid(z):
        b, a = unpack(z)
        if np.any(np.abs(np.roots(a)) >= 0.9999):
            return np.full(sum((y.size - k0 + stride - 1) // stride for y, k0 in zip(ys, k0s)), 1e3)
        return np.concatenate([(filt(b, a, x) - y)[k0::stride] for x, y, k0 in zip(xs, ys, k0s)])

    z0 = np.concatenate([a0[1:], b0])
    try:
        sol = optimize.least_squares(resid, z0, max_nfev=max_nfev, x_scale="jac")
    except (ValueError, np.linalg.LinAlgError):
        return m
    if np.sum(resid(sol.x) ** 2) < np.sum(resid(z0) ** 2):
        return unpack(sol.x)
    return m


def _fit_h(Fs, ys, rows, k0s):
    """H's coefficients (features of Fs, then the offset), fitted with the slow trend columns (not returned)."""
    Ts = _trends([y.size for y in ys], k0s)
    X = np.vstack([np.column_stack([F[k0:], T[k0:], np.ones(F.shape[0] - k0)]) for F, T, k0 in zip(Fs, Ts, k0s)])
    y = np.concatenate([y[k0:] for y, k0 in zip(ys, k0s)])
    if X.shape[0] > rows:
        s = int(np.ceil(X.shape[0] / rows))
        X, y = X[::s], y[::s]
    th = _lstsq(X, y, RIDGE)
    nf = Fs[0].shape[1]
    return np.concatenate([th[:nf], th[-1:]])


def _refine_bw(best, vs, polys, sos, ylp, k0s, rows, v_rest):
    """(score, None, (beta, gamma)) refined from the grid point by Nelder-Mead on (log beta, gamma / beta).

    The grid is coarse (a factor 1.6 in beta); a shape error that is small inside a narrow calibration grows
    when the model is run over a wider range, and is then mistaken for missing physics."""
    def score(z):
        beta, gr = float(np.exp(z[0])), float(np.clip(z[1], -0.95, 0.95))
        hs = [sig.sosfiltfilt(sos, bouc_wen_h(v, beta, gr * beta, v_rest)) for v in vs]
        return _cv_h([np.column_stack([h, p]) for h, p in zip(hs, polys)], ylp, k0s, rows)
    beta0, gamma0 = best[2]
    z0 = np.array([np.log(beta0), gamma0 / beta0])
    sol = optimize.minimize(score, z0, method="Nelder-Mead",
                            options={"maxfev": 40, "xatol": 0.01, "fatol": 1e-4 * best[0],
                                     "initial_simplex": [z0, z0 + [0.25, 0.0], z0 + [0.0, 0.15]]})
    if sol.fun < best[0]:
        beta = float(np.exp(sol.x[0]))
        return (float(sol.fun), None, (beta, float(np.clip(sol.x[1], -0.95, 0.95)) * beta))
    return best


def fit_base(recordings, n_plays: int = 10, max_rows: int = MAX_ROWS, u_rest: float = 0.0,
             settle_s: float = 0.5) -> dict:
    """Fit the base model (kind ``refined`` without terms) to calibration recordings.

    Parameters
    ----------
    recordings : sequence of Recording
        Calibration data: ``t`` [s], ``u`` [V], ``y`` [um], one sample rate.
    n_plays : int
        Number of play operators (thresholds evenly spread over the normalized range).
    max_rows : int
        Samples entering each least-squares problem (evenly strided).
    u_rest : float
        Rest drive [V] the stage starts from (plays relaxed there; 0 V at power-up).
    settle_s : float
        The first ``settle_s`` seconds of each recording [s] (the stage settling
        from an unknown state) do not enter the fits.

    Returns
    -------
    dict
        Parameters of kind ``refined`` (``terms`` empty) plus ``base_info``: the
        chosen dynamics order and the cross-validated simulation NRMSE per order.
    """
    if not recordings:
        raise IdentError("base model: no calibration recordings")
    fs = [r.sample_rate_hz for r in recordings]
    if max(fs) / min(fs) - 1 > 0.01:
        raise IdentError(f"base model: calibration recordings have different sample rates {fs}")
    umin = min(float(np.min(r.u)) for r in recordings)
    umax = max(float(np.max(r.u)) for r in recordings)
    if umax - umin <= 0:
        raise IdentError("base model: the calibration drive is constant; nothing to identify")
    mid, half = 0.5 * (umax + umin), 0.5 * (umax - umin)
    r = R_MAX * (np.arange(n_plays) + 0.5) / n_plays
    v_rest = (u_rest - mid) / half
    vs = [(rec.u - mid) / half for rec in recordings]
    ys = [np.asarray(rec.y, float) for rec in recordings]
    # first pass on zero-phase low-passed data: a resonance in the data must not bend H
    fs0 = float(np.mean(fs))
    k0s = [min(int(round(settle_s * fs0)), len(y) // 2) for y in ys]
    sos = sig.butter(2, min(LP_FIRST_HZ, 0.2 * fs0), fs=fs0, output="sos")
    ylp = [sig.sosfiltfilt(sos, y) for y in ys]
    lp = (lambda F: sig.sosfiltfilt(sos, F, axis=0))
    # hysteresis class: PI (plays) or Bouc-Wen (beta, gamma on a grid), by 2-fold block CV
    Fpi = [_features(v, r, v_rest) for v in vs]
    cls = {"pi": (_cv_h([lp(F) for F in Fpi], ylp, k0s, max_rows), Fpi, None)}
    best_bw = None
    polys = [lp(np.column_stack([v, v ** 2, v ** 3])) for v in vs]
    for beta in BW_BETAS:
        for gr in BW_GAMMA_RATIOS:
            hs = [sig.sosfiltfilt(sos, bouc_wen_h(v, beta, gr * beta, v_rest)) for v in vs]
            sc = _cv_h([np.column_stack([h, p]) for h, p in zip(hs, polys)], ylp, k0s, max_rows)
            if best_bw is None or sc < best_bw[0]:
                best_bw = (sc, None, (beta, gr * beta))
    best_bw = _refine_bw(best_bw, vs, polys, sos, ylp, k0s, max_rows, v_rest)
    best_bw = (best_bw[0], [_bw_features(v, *best_bw[2], v_rest) for v in vs], best_bw[2])
    cls["bouc_wen"] = best_bw
    htype = "bouc_wen" if cls["bouc_wen"][0] < cls["pi"][0] else "pi"
    Fs = cls[htype][1]
    th = _fit_h([lp(F) for F in Fs], ylp, max_rows, k0s)
    b, a = np.array([1.0]), np.array([1.0])
    info = {}
    for it in range(2):
        xs = [F @ th[:-1] for F in Fs]
        yo = [y - th[-1] for y in ys]
        (b, a), best, scores = _select_dynamics(xs, yo, k0s, max_rows, refine=it == 1)
        info = {"dynamics_order": best, "cv_sim_rmse_um": {str(k): v for k, v in scores.items()}}
        Gs = [filt(b, a, F) for F in Fs]
        th = _fit_h(Gs, ys, max_rows, k0s)
    n = n_plays if htype == "pi" else 1
    # the cubic is trusted over the drive range the fit saw (settled samples; the conditioning sweep before
    # settle_s reaches further but does not enter the fit) and continued as a line beyond it
    v_lo = min(float(np.min(v[k0:])) for v, k0 in zip(vs, k0s))
    v_hi = max(float(np.max(v[k0:])) for v, k0 in zip(vs, k0s))
    hyst = {"type": htype, "poly": th[n:n + 3].tolist(), "v_lo": v_lo, "v_hi": v_hi, "offset": float(th[-1]),
            "v_rest": float(v_rest)}
    if htype == "pi":
        hyst.update(r=r.tolist(), w=th[:n].tolist())
    else:
        hyst.update(beta=float(cls["bouc_wen"][2][0]), gamma=float(cls["bouc_wen"][2][1]), c_h=float(th[0]))
    info["hysteresis_cv_rmse_um"] = {"pi": float(cls["pi"][0]), "bouc_wen": float(cls["bouc_wen"][0])}
    params = {
        "fs_hz": float(np.mean(fs)),
        "u_mid": mid, "u_half": half,
        "hysteresis": hyst,
        "dynamics": {"b": np.asarray(b).tolist(), "a": np.asarray(a).tolist()},
        "terms": {},
        "base_info": info,
    }
    return params


def fit_dynamics(xs, ys, k0s, max_rows: int = 60_000, band: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Dynamics G (unit static gain) from H outputs ``xs`` [um] to outputs ``ys`` [um] (offset removed).

    ARX of order 0, 2 or 4 by the base model's rule (a higher order kept when it lowers
    the simulation error on these data by 5 %); no output-error refinement (this is
    called once per setting of a drive-side term, so it must be cheap).

    band : float, optional
        The calibration's band [cycles/sample] for the plausibility rule (default: from ``xs``).

    Returns
    -------
    (b, a) : tuple of ndarray
        Discrete transfer function at the recordings' rate.
    """
    (b, a), _, _ = _select_dynamics(xs, ys, k0s, max_rows, refine=False, band=band)
    return np.asarray(b, float), np.asarray(a, float)


def _select_dynamics(xs, ys, k0s, max_rows, refine, band=None):
    """ARX of each order in ORDERS (output-error refined when ``refine``); returns ((b, a), order, scores).

    Order by simulation error on all calibration data: each step up in order must lower it by 5 % and be
    plausible (interleaved time blocks cannot cross-validate a chirp's band)."""
    models, scores = {}, {}
    for order in ORDERS:
        m = _arx([x[k0:] for x, k0 in zip(xs, k0s)], [y[k0:] for y, k0 in zip(ys, k0s)], order, max_rows)
        if m is not None and order > 0 and refine:
            m = _oe_refine(m, xs, ys, k0s)
        models[order] = m
        scores[order] = _sim_rmse(m, xs, ys, k0s) if m is not None else float("inf")
    best = 0
    band = band_cps(xs, k0s) if band is None else band
    for order in ORDERS[1:]:
        if plausible(models[order], band) and scores[order] < 0.95 * scores[best]:
            best = order
    return models[best], best, scores
