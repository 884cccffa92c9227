"""Model kind ``rkp``: rate-dependent KP model, batch least squares and the online law.

    y(k) = sum_j psi_j[v](k) w_j(k) + (theta_lin . F(k)) v(k) + c,
    w(k) = Theta F(rate(k)),   F_m = exp(-((rate - c_m) / sigma_m)^2 / 2)

``v`` is the drive normalized to [-1, 1], ``psi_j`` the KP operators of
:mod:`piezoctl.models.kp` (reset state), ``rate`` the (optionally low-pass
filtered) rate of ``v`` [FS/s] and ``F`` ``M`` Gaussian radial basis functions
of it (the paper uses 13 "neurons"). The KP part is exactly
:func:`piezoctl.models.kp.rkp_model`; the rate-dependent linear term and the
offset are this kind's additions (``--rkp-linear off`` drops the former).

Since ``y = vec(Theta) . (psi (x) F)`` is linear in ``Theta`` the batch fit is
least squares over the ``N M`` Kronecker features ``psi_j F_m``. A
single-frequency recording excites only a few Gaussians and leaves the
others' weights undetermined; a penalty on the differences of ``Theta``
between neighbouring Gaussians (``--rkp-smooth``) makes them copy their
neighbours instead of decaying to 0, plus a tiny ridge (``--rkp-ridge``).
:func:`online_gradient` is the paper's adaptive law
``dTheta/dt = -g psi F^T e`` (``g = 0.8`` in the paper), integrated by Euler.

Parameters (``params``): ``u_min``, ``u_max`` [V]; grid ``L``, ``nmin``,
``nmax``, ``s``; ``centers``, ``widths`` [normalized drive per second, FS/s];
``filt`` (rate filter coefficient, 1 = none); ``theta`` (N x M) [um];
``theta_lin`` (M) [um per FS]; ``offset`` [um].
"""

from __future__ import annotations

import numpy as np

from ..models import kp as kpref
from .common import IdentError, check_positive_int, drive_range, normalize, offset_params, solve_linear
from .kp import grid_of

KIND = "rkp"
DESCRIPTION = "rate-dependent KP: density Theta F(rate), Gaussian RBFs of the rate (batch least squares)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "rate_basis",
           "kron_features", "online_gradient", "smoothness_penalty"]


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--rkp-``)."""
    parser.add_argument("--rkp-levels", type=int, default=8, metavar="L",
                        help="KP grid intervals per axis (default 8: 36 operators)")
    parser.add_argument("--rkp-neurons", type=int, default=13, metavar="M",
                        help="Gaussian RBFs of the rate (default 13, as in the paper)")
    parser.add_argument("--rkp-rate-max", type=float, default=None, metavar="R",
                        help="RBF centers span [-R, R] [FS/s] (default: the 99.9th percentile of |rate| "
                             "over the data)")
    parser.add_argument("--rkp-rate-cutoff-hz", type=float, default=50.0, metavar="HZ",
                        help="cutoff of the first-order low-pass of the rate estimate [Hz] "
                             "(default 50; 0 for none)")
    parser.add_argument("--rkp-ridge", type=float, default=1e-6, metavar="LAMBDA",
                        help="relative ridge weight of the batch least squares (default 1e-6)")
    parser.add_argument("--rkp-smooth", type=float, default=1.0, metavar="LAMBDA",
                        help="relative weight of a penalty on differences of Theta between "
                             "neighbouring Gaussians: rates the data do not excite take the "
                             "neighbours' density instead of 0 (default 1)")
    parser.add_argument("--rkp-rate-span", type=float, default=2.0, metavar="K",
                        help="without --rkp-rate-max, centers span K times the data's 99.9th "
                             "percentile |rate| (default 2)")
    parser.add_argument("--rkp-linear", choices=("on", "off"), default="on",
                        help="rate-dependent linear term (theta_lin . F) v (default on)")
    parser.add_argument("--rkp-max-rows", type=int, default=40_000, metavar="N",
                        help="at most N samples enter the batch fit (N M (L(L+1)/2) features "
                             "each; default 40000)")


def rate_basis(rate_max: float, M: int) -> tuple[np.ndarray, np.ndarray]:
    """Centers evenly on [-rate_max, rate_max] and widths equal to their spacing [FS/s]."""
    if M == 1:
        return np.zeros(1), np.array([rate_max])
    c = np.linspace(-rate_max, rate_max, M)
    return c, np.full(M, c[1] - c[0])


def _dt(t: np.ndarray) -> float:
    return float(np.median(np.diff(np.asarray(t, dtype=np.float64))))


def kron_features(psi: np.ndarray, F: np.ndarray, v: np.ndarray | None = None):
    """Row-selector of the Kronecker features ``[psi_j F_m (j-major), v F_m]``.

    Returns a callable ``rows -> ndarray (len(rows), N M [+ M])`` so that the
    large matrix is never built whole.
    """
    N, M = psi.shape[1], F.shape[1]

    def rows(sel):
        p, f = psi[sel], F[sel]
        out = (p[:, :, None] * f[:, None, :]).reshape(len(sel), N * M)
        if v is not None:
            out = np.hstack([out, v[sel, None] * f])
        return out
    return rows


def smoothness_penalty(rows: int, M: int) -> np.ndarray:
    """``D^T D`` for first differences along the Gaussians of each row of a (rows, M) weight array.

    The weights are flattened row-major (``theta[j, m]`` at ``j M + m``), then
    the ``theta_lin`` row if any; each row gets the same (M-1) x M difference.
    """
    if M < 2:
        return np.zeros((rows * M, rows * M))
    D = np.diff(np.eye(M), axis=0)
    return np.kron(np.eye(rows), D.T @ D)


def fit(recordings, options) -> dict:
    """Fit an RKP model to recordings (batch least squares over Kronecker features).

    Parameters
    ----------
    recordings : sequence of Recording
        Data files (``u`` [V], ``y`` [um]).
    options : mapping
        ``rkp_levels``, ``rkp_neurons``, ``rkp_rate_max``,
        ``rkp_rate_cutoff_hz``, ``rkp_ridge``, ``rkp_linear``,
        ``rkp_max_rows`` and the common ``u_range``, ``offset``, ``max_fit_rows``.

    Returns
    -------
    dict
        Parameters (see the module docstring).
    """
    L = check_positive_int("--rkp-levels", options.get("rkp_levels", 8))
    M = check_positive_int("--rkp-neurons", options.get("rkp_neurons", 13))
    grid = kpref.kp_grid(L, -1.0, 1.0)
    u_min, u_max = drive_range(recordings, options.get("u_range"))
    fc = options.get("rkp_rate_cutoff_hz", 50.0)
    if fc is not None and fc == 0:
        fc = None
    if fc is not None and not fc > 0:
        raise IdentError(f"--rkp-rate-cutoff-hz {fc:g}: must be >= 0")
    dts = [_dt(r.t) for r in recordings]
    if fc is not None and max(dts) / min(dts) > 1.01:
        raise IdentError("--rkp-rate-cutoff-hz needs data files of one sample rate")
    filt = 1.0 if fc is None else kpref.lowpass_coefficient(fc, dts[0])
    vs = [normalize(r.u, u_min, u_max) for r in recordings]
    # The reference model starts from the reset state (previous input at nmin); the
    # rate at the first sample therefore includes the jump from nmin (see simulate).
    rates = [kpref.rate_estimate(v, dt, filt, grid.nmin) for v, dt in zip(vs, dts)]
    rmax = options.get("rkp_rate_max")
    if rmax is None:
        # 99.9th percentile of |rate|: a start-up step (and the first sample's jump
        # from the reset state) must not stretch the basis over rates never held.
        span = float(options.get("rkp_rate_span", 2.0))
        if not span > 0:
            raise IdentError(f"--rkp-rate-span {span:g}: must be > 0")
        rmax = span * float(np.percentile(np.abs(np.concatenate(rates)), 99.9))
    if not rmax > 0:
        raise IdentError("the drive rate is zero everywhere: give --rkp-rate-max")
    centers, widths = rate_basis(float(rmax), M)
    linear = options.get("rkp_linear", "on") == "on"
    feats = []
    for v, rate in zip(vs, rates):
        psi = kpref.kp_outputs(v, grid)
        F = kpref.gaussian_rbf(rate, centers, widths)
        feats.append(kron_features(psi, F, v if linear else None))
    max_rows = min(int(options.get("rkp_max_rows", 40_000)), int(options.get("max_fit_rows", 200_000)))
    penalty = smoothness_penalty(grid.N + (1 if linear else 0), M) * float(options.get("rkp_smooth", 1.0))
    res = solve_linear(feats, [r.y for r in recordings], offset=options.get("offset", "shared"),
                       max_rows=max_rows, ridge=float(options.get("rkp_ridge", 1e-6)),
                       penalty=penalty, block=2048)
    NM = grid.N * M
    params = {
        "u_min": u_min, "u_max": u_max,
        "L": grid.L, "nmin": grid.nmin, "nmax": grid.nmax, "s": grid.s, "N": grid.N, "M": M,
        "centers": centers, "widths": widths, "filt": filt,
        "rate_cutoff_hz": fc,
        "theta": res.coef[:NM].reshape(grid.N, M),
        "theta_lin": res.coef[NM:NM + M] if linear else np.zeros(M),
        **offset_params(res, options),
    }
    return params


def simulate(params: dict, t, u, u2=None) -> np.ndarray:
    """Model output y [um] for drive u [V] at times t [s] (``u2`` unused)."""
    grid = grid_of(params)
    theta = np.asarray(params["theta"], dtype=np.float64)
    M = int(params["M"])
    if theta.shape != (grid.N, M):
        raise IdentError(f"rkp model: theta has shape {theta.shape}, expected ({grid.N}, {M})")
    v = normalize(u, params["u_min"], params["u_max"])
    dt = _dt(t)
    fc = params.get("rate_cutoff_hz")
    # the filter coefficient follows this input's sample period (same cutoff in Hz)
    filt = 1.0 if fc is None else kpref.lowpass_coefficient(float(fc), dt)
    c, w = params["centers"], params["widths"]
    y = kpref.rkp_model(v, grid, theta, dt, c, w, filt)
    theta_lin = np.asarray(params.get("theta_lin", np.zeros(M)), dtype=np.float64)
    if np.any(theta_lin):
        F = kpref.rate_features(v, dt, c, w, filt, grid.nmin)
        y = y + (F @ theta_lin) * v
    return y + float(params["offset"])


def online_gradient(psi: np.ndarray, F: np.ndarray, y: np.ndarray, g: float, dt: float,
                    theta0: np.ndarray | None = None, passes: int = 1,
                    record_every: int = 0):
    """The paper's online gradient law ``dTheta/dt = -g psi F^T e``, Euler-integrated.

    At each sample ``k``: ``yhat = psi_k . (Theta F_k)``, ``e = yhat - y_k`` and
    ``Theta <- Theta - g dt e psi_k F_k^T``.

    Parameters
    ----------
    psi : ndarray, shape (T, N)
        KP operator outputs [FS].
    F : ndarray, shape (T, M)
        Rate features [1].
    y : ndarray, shape (T,)
        Measured output [um] (offset removed by the caller).
    g : float
        Adaptation gain [1 / (um s)] in the paper's units (0.8 in the paper).
    dt : float
        Sample period [s].
    theta0 : ndarray, shape (N, M), optional
        Initial estimate (default zeros).
    passes : int
        How many times the data are run through (>= 1).
    record_every : int
        If > 0, also return ``Theta`` every this many samples.

    Returns
    -------
    theta : ndarray, shape (N, M)
        Final estimate.
    err : ndarray, shape (passes * T,)
        Prediction error ``e`` before each update [um].
    history : list of ndarray
        Snapshots of ``Theta`` (only when ``record_every > 0``).
    """
    psi = np.asarray(psi, dtype=np.float64)
    F = np.asarray(F, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    T, N = psi.shape
    M = F.shape[1]
    theta = np.zeros((N, M)) if theta0 is None else np.array(theta0, dtype=np.float64)
    gain = float(g) * float(dt)
    err = np.empty(passes * T)
    history = []
    i = 0
    for _ in range(int(passes)):
        for k in range(T):
            p = psi[k]
            f = F[k]
            e = p @ theta @ f - y[k]
            err[i] = e
            theta -= (gain * e) * np.outer(p, f)
            i += 1
            if record_every and i % record_every == 0:
                history.append(theta.copy())
    return theta, err, history
