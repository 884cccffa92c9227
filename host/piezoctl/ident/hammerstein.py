"""Model kind ``hammerstein``: distributed Hammerstein model of cross-axis coupling.

The coupled displacement y of this axis [um] caused by the drive u of the other
axis [V] (recording column ``u2``), at the other axis' position x [um] (column
``x2``, or the drive mapped to a position), is

.. math::

    y(t, x) = \\sum_{c=1}^{N_c} G_c(z^{-1}, x)\\, N_c(u(t), x),\\qquad
    G_c = \\sum_{i=1}^{m} \\rho(x)^T \\xi_{c,i} L_i(z^{-1}),\\qquad
    N_c = \\sum_{j=1}^{n} \\psi(x)^T \\eta_{c,j}\\, g_j(u),

with Laguerre filters :math:`L_i` (:mod:`piezoctl.ident.laguerre`), position
polynomials :math:`\\rho(x) = \\psi(x) = [1, x_n, \\dots, x_n^{d}]` and input functions
:math:`g = \\{u_n^k, k \\in K;\\ \\sin(j u_n), \\cos(j u_n), j = 1..J\\}` (paper:
m = 2, q = 0.1, T = 2, d = 7, K = {0, 1, 2, 3, 7}, J = 5, so n = 15; N_c = 2).

Normalization
    u and x enter every basis function normalized to [-1, 1] over the training
    range: :math:`u_n = (u - u_c)/u_s`, :math:`x_n = (x - x_c)/x_s` (centre and
    half range stored in the parameters). Raw volts and micrometres would put
    :math:`9^7 \\approx 5\\cdot10^6` next to 1 in g and :math:`240^7` in
    :math:`\\rho\\otimes\\psi`: the Kronecker regressor would have a condition number
    beyond double precision. The trigonometric functions use the normalized
    input too (arguments up to J rad).

Identification (one linear least-squares problem over all positions)
    With :math:`\\theta = \\xi \\otimes \\eta` (:math:`\\xi` indexed by filter i and
    :math:`\\rho` entry a, :math:`\\eta` by function j and :math:`\\psi` entry b), the
    model is linear in :math:`\\theta`:
    :math:`y(t) = \\phi(t)^T\\theta`,
    :math:`\\phi_{(i,a),(j,b)}(t) = \\rho_a(x(t))\\, L_i[g_j(u)\\,\\psi_b(x)](t)`
    (the Kronecker regressor :math:`L \\otimes \\rho \\otimes g \\otimes \\psi`; the
    filter acts on the nonlinearity output, so a time-varying x is handled
    consistently with :func:`predict`). The Gram matrix is accumulated from the
    moments :math:`\\sum_t x_n^k f f^T` (k = 0..2d) of the filtered signals f — per
    distinct position when x is constant within each record — so the
    (m (d+1) n (d+1))-column regressor (1920 columns at the paper's settings) is
    never stored. Products :math:`\\rho_a\\psi_b` make the problem rank deficient
    (only :math:`x^{a+b}` is seen), so the solution is the minimum-norm one in
    column-equilibrated coordinates (eigen-decomposition of the scaled Gram
    matrix, eigenvalues below ``rcond`` times the largest dropped).

Channels (SVD)
    :math:`\\theta` is reshaped into the :math:`n(d+1) \\times m(d+1)` matrix
    :math:`\\Theta^T` (rows: :math:`\\eta` index, columns: :math:`\\xi` index),
    :math:`\\Theta^T = W \\Sigma V^T`, and channel c keeps :math:`\\eta_c = w_c`,
    :math:`\\xi_c = \\sigma_c v_c` for c = 1..N_c.

Channel refinement (our addition; ``refine = 0`` gives the paper's method)
    Because only the products :math:`\\rho_a\\psi_b` are identifiable, the
    minimum-norm :math:`\\Theta` spreads a position dependence over several
    (a, b) pairs and is generally not of rank :math:`N_c` even when the true
    model is; truncating its SVD can then lose most of the fit. ``refine``
    Levenberg-Marquardt iterations on all :math:`\\xi_c, \\eta_c` (the model is
    bilinear in them, so the Jacobian is exact and cheap) start from the SVD
    channels and find a rank-:math:`N_c` model that fits the data; a step is kept
    only if it lowers the training residual (history in ``refine_rss``).

Laguerre filters start at the equilibrium of each record's first sample.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

from .laguerre import laguerre_filter

KIND = "hammerstein"
DESCRIPTION = "distributed Hammerstein cross-coupling model (Laguerre dynamics x input functions, position polynomials)"

__all__ = ["KIND", "DESCRIPTION", "add_options", "fit", "simulate", "predict", "fit_arrays",
           "input_basis", "poly_basis", "DEFAULTS"]

DEFAULTS = {
    "m": 2, "q": 0.1, "T": 2.0, "degree": 7, "powers": [0, 1, 2, 3, 7], "harmonics": 5,
    "channels": 2, "rcond": 1e-12, "position": "auto", "x_per_volt": 1.0, "refine": 20,
}


def add_options(parser) -> None:
    """``identify`` options of this kind (prefix ``--hammerstein-``)."""
    d = DEFAULTS
    parser.add_argument("--hammerstein-m", type=int, default=d["m"], help="Laguerre filters m (default 2)")
    parser.add_argument("--hammerstein-q", type=float, default=d["q"], help="Laguerre pole q (default 0.1)")
    parser.add_argument("--hammerstein-T", type=float, default=d["T"],
                        help="Laguerre sampling interval T, same time unit as q (default 2)")
    parser.add_argument("--hammerstein-degree", type=int, default=d["degree"],
                        help="degree d of the position polynomials rho, psi (default 7)")
    parser.add_argument("--hammerstein-powers", type=int, nargs="+", default=d["powers"],
                        help="powers k of u_n^k in g (default 0 1 2 3 7)")
    parser.add_argument("--hammerstein-harmonics", type=int, default=d["harmonics"],
                        help="J: sin(j u_n), cos(j u_n), j = 1..J in g (default 5)")
    parser.add_argument("--hammerstein-channels", type=int, default=d["channels"],
                        help="channels Nc kept from the SVD (default 2)")
    parser.add_argument("--hammerstein-rcond", type=float, default=d["rcond"],
                        help="relative eigenvalue cutoff of the scaled Gram matrix (default 1e-12)")
    parser.add_argument("--hammerstein-refine", type=int, default=d["refine"],
                        help="Levenberg-Marquardt iterations refining the Nc channels after the "
                             "SVD (0: the paper's SVD split only; default 20)")
    parser.add_argument("--hammerstein-position", choices=("auto", "x2", "u2"), default=d["position"],
                        help="position x: column x2, or u2 times --hammerstein-x-per-volt "
                             "(auto: x2 when every file has it)")
    parser.add_argument("--hammerstein-x-per-volt", type=float, default=d["x_per_volt"],
                        help="um per volt when x is mapped from u2 (default 1)")


def _opt(options, name):
    if options is None:
        return DEFAULTS[name]
    v = options.get(f"hammerstein_{name}", None) if hasattr(options, "get") else None
    return DEFAULTS[name] if v is None else v


def poly_basis(xn, degree: int) -> np.ndarray:
    """Columns ``[1, xn, ..., xn**degree]`` of a normalized position, shape (N, degree + 1)."""
    xn = np.asarray(xn, dtype=float)
    return xn[:, None] ** np.arange(int(degree) + 1)[None, :]


def input_basis(un, powers, harmonics: int) -> np.ndarray:
    """Input functions g(u_n): ``u_n**k`` for k in powers, then sin(j u_n), cos(j u_n), j = 1..J.

    Parameters
    ----------
    un : array_like, shape (N,)
        Normalized input (about [-1, 1]).
    powers : sequence of int
        Exponents k >= 0.
    harmonics : int
        J >= 0.

    Returns
    -------
    ndarray, shape (N, len(powers) + 2 J)
    """
    un = np.asarray(un, dtype=float)
    cols = [un ** int(k) for k in powers]
    cols += [np.sin(j * un) for j in range(1, int(harmonics) + 1)]
    cols += [np.cos(j * un) for j in range(1, int(harmonics) + 1)]
    return np.column_stack(cols)


def _norm(v, c, s):
    return (np.asarray(v, dtype=float) - c) / s


def _filtered(p, un, xn):
    """F (N, m, n q): Laguerre outputs of g_j(u) psi_b(x), and R (N, d+1) = rho(x)."""
    g = input_basis(un, p["powers"], p["harmonics"])
    r = poly_basis(xn, p["degree"])
    z = (g[:, :, None] * r[:, None, :]).reshape(un.size, -1)
    return laguerre_filter(z, p["m"], p["q"], p["T"]), r


def fit_arrays(u_list, x_list, y_list, **settings) -> dict:
    """Fit the model to records given as arrays (see :func:`fit` for recordings).

    Parameters
    ----------
    u_list : sequence of ndarray
        Drive of the other axis per record [V].
    x_list : sequence of ndarray
        Position per sample per record [um] (constant within a record is fine).
    y_list : sequence of ndarray
        Coupled displacement per record [um].
    **settings
        Any of :data:`DEFAULTS` (``m, q, T, degree, powers, harmonics, channels, rcond,
        refine``).

    Returns
    -------
    dict
        Parameters: the settings, the normalization (``u_center, u_scale`` [V],
        ``x_center, x_scale`` [um]), ``channels`` (list of ``{"xi": m x (d+1),
        "eta": n x (d+1)}``), ``sigma`` (all singular values), ``rank`` (kept
        eigenvalues of the scaled Gram matrix), ``theta`` (full solution, for
        :func:`predict` with ``full=True``).
    """
    p = {k: settings.get(k, DEFAULTS[k]) for k in ("m", "q", "T", "degree", "powers", "harmonics",
                                                  "channels", "rcond")}
    p["m"], p["degree"], p["harmonics"], p["channels"] = (int(p["m"]), int(p["degree"]),
                                                         int(p["harmonics"]), int(p["channels"]))
    p["powers"] = [int(k) for k in p["powers"]]
    if p["m"] < 1 or p["degree"] < 0 or p["harmonics"] < 0 or p["channels"] < 1 or \
            any(k < 0 for k in p["powers"]) or len(p["powers"]) + 2 * p["harmonics"] < 1:
        raise ValueError("hammerstein: need m >= 1, degree >= 0, powers >= 0, harmonics >= 0, channels >= 1")
    if not (len(u_list) == len(x_list) == len(y_list)) or not u_list:
        raise ValueError("hammerstein: u, x, y lists must be non-empty and of equal length")
    uall = np.concatenate([np.asarray(u, float) for u in u_list])
    xall = np.concatenate([np.asarray(x, float) for x in x_list])
    if not (np.all(np.isfinite(uall)) and np.all(np.isfinite(xall))):
        raise ValueError("hammerstein: u or x has non-finite values")
    u_c, u_s = 0.5 * (uall.max() + uall.min()), 0.5 * (uall.max() - uall.min())
    if u_s <= 0:
        raise ValueError("hammerstein: the drive u2 is constant: nothing to identify")
    x_c, x_s = 0.5 * (xall.max() + xall.min()), 0.5 * (xall.max() - xall.min())
    if x_s <= 0:
        x_s = 1.0
    p.update(u_center=float(u_c), u_scale=float(u_s), x_center=float(x_c), x_scale=float(x_s))
    m, dp = p["m"], p["degree"] + 1
    nfun = len(p["powers"]) + 2 * p["harmonics"]
    nq = nfun * dp
    k_mom = 2 * p["degree"] + 1
    mom = np.zeros((k_mom, m * nq, m * nq))
    rhs = np.zeros((dp, m * nq))
    for u, x, y in zip(u_list, x_list, y_list):
        y = np.asarray(y, float)
        un, xn = _norm(u, u_c, u_s), _norm(x, x_c, x_s)
        f, _ = _filtered(p, un, xn)
        f = f.reshape(un.size, m * nq)
        vals, inv = np.unique(xn, return_inverse=True)
        if vals.size <= max(1, un.size // 50):
            for g, xv in enumerate(vals):  # few distinct positions: one Gram per position
                fg = f[inv == g]
                ff = fg.T @ fg
                fy = fg.T @ y[inv == g]
                pw = xv ** np.arange(k_mom)
                mom += pw[:, None, None] * ff[None]
                rhs += pw[:dp, None] * fy[None]
        else:
            for k in range(k_mom):
                wk = xn ** k
                mom[k] += f.T @ (f * wk[:, None])
                if k < dp:
                    rhs[k] += f.T @ (y * wk)
    # Gram[(i,a,s),(j,c,t)] = mom[a+c][(i,s),(j,t)], s, t over (function, psi entry)
    a_idx = np.arange(dp)
    g6 = mom[a_idx[:, None] + a_idx[None, :]].reshape(dp, dp, m, nq, m, nq)
    npar = m * dp * nq
    gram = g6.transpose(2, 0, 3, 4, 1, 5).reshape(npar, npar)
    b = rhs.reshape(dp, m, nq).transpose(1, 0, 2).reshape(npar)
    dsc = np.sqrt(np.maximum(np.diag(gram), 1e-300))
    gs = gram / dsc[:, None] / dsc[None, :]
    lam, vec = linalg.eigh(gs)
    keep = lam > float(p["rcond"]) * lam[-1]
    theta = (vec[:, keep] @ ((vec[:, keep].T @ (b / dsc)) / lam[keep])) / dsc
    big = theta.reshape(m * dp, nq)  # rows: xi index (i, a); columns: eta index (j, b)
    w, sig, vt = np.linalg.svd(big.T, full_matrices=False)
    nc = min(p["channels"], sig.size)
    chans = []
    for c in range(nc):
        chans.append({"eta": w[:, c].reshape(nfun, dp).tolist(),
                      "xi": (sig[c] * vt[c]).reshape(m, dp).tolist()})
    p.update(channels_fit=chans, sigma=sig.tolist(), rank=int(np.count_nonzero(keep)),
             theta=theta.tolist())
    p["refine"] = int(settings.get("refine", DEFAULTS["refine"]))
    if p["refine"] > 0:
        p["channels_fit"], p["refine_rss"] = _refine(p, u_list, x_list, y_list, chans, p["refine"])
    return p


def _pinv_solve(gram, b, rcond=1e-12):
    dsc = np.sqrt(np.maximum(np.diag(gram), 1e-300))
    lam, vec = linalg.eigh(gram / dsc[:, None] / dsc[None, :])
    keep = lam > rcond * max(lam[-1], 1e-300)
    return (vec[:, keep] @ ((vec[:, keep].T @ (b / dsc)) / lam[keep])) / dsc


def _refine(p, u_list, x_list, y_list, chans, iterations):
    """Levenberg-Marquardt refinement of the channels' xi and eta (see the module notes)."""
    m, dp = p["m"], p["degree"] + 1
    nc = len(chans)
    xi = np.array([c["xi"] for c in chans])    # (nc, m, dp)
    eta = np.array([c["eta"] for c in chans])  # (nc, n, dp)
    recs = []
    for u, x, y in zip(u_list, x_list, y_list):
        un = _norm(u, p["u_center"], p["u_scale"])
        xn = _norm(np.broadcast_to(np.asarray(x, float), un.shape), p["x_center"], p["x_scale"])
        f, r = _filtered(p, un, xn)  # f (N, m, n*dp)
        recs.append((f, r, np.asarray(y, float)))
    nx, ns = nc * m * dp, eta[0].size

    def model(xi_, eta_, f, r):
        return np.einsum("tis,ta,cia,cs->t", f, r, xi_, eta_.reshape(nc, -1), optimize=True)

    def rss(xi_, eta_):
        return sum(float(np.sum((y - model(xi_, eta_, f, r)) ** 2)) for f, r, y in recs)

    def normal_eq(xi_, eta_):
        # y is bilinear: d y / d xi[c,i,a] = rho_a L_i[N_c]; d y / d eta[c,s] = sum_i (rho.xi[c,i]) F_is
        g = np.zeros((nx + nc * ns,) * 2)
        b = np.zeros(nx + nc * ns)
        for f, r, y in recs:
            lnc = np.einsum("tis,cs->tci", f, eta_.reshape(nc, -1))
            jx = (lnc[:, :, :, None] * r[:, None, None, :]).reshape(len(y), nx)
            gain = np.einsum("ta,cia->tci", r, xi_)
            je = np.einsum("tci,tis->tcs", gain, f).reshape(len(y), nc * ns)
            jac = np.hstack([jx, je])
            g += jac.T @ jac
            b += jac.T @ (y - model(xi_, eta_, f, r))
        return g, b

    best = rss(xi, eta)
    hist = [best]
    lam = 1e-3
    g, b = normal_eq(xi, eta)
    for _ in range(iterations):
        dg = np.diag(g).copy()
        step = _pinv_solve(g + lam * np.diag(np.maximum(dg, 1e-12 * dg.max())), b)
        xi_new = xi + step[:nx].reshape(xi.shape)
        eta_new = eta + step[nx:].reshape(eta.shape)
        cur = rss(xi_new, eta_new)
        if cur < best:
            xi, eta, best = xi_new, eta_new, cur
            hist.append(cur)
            lam = max(lam / 3.0, 1e-9)
            g, b = normal_eq(xi, eta)
        else:
            lam *= 4.0
            if lam > 1e6:
                break
    out = [{"eta": eta[c].tolist(), "xi": xi[c].tolist()} for c in range(nc)]
    return out, hist


def predict(params: dict, u, x, full: bool = False) -> np.ndarray:
    """Model output y [um] for the other axis' drive u [V] at positions x [um].

    Parameters
    ----------
    params : dict
        From :func:`fit_arrays` / :func:`fit`.
    u : array_like, shape (N,)
        Drive of the other axis [V].
    x : array_like, shape (N,) or float
        Position [um] per sample (a scalar for a fixed position).
    full : bool
        Use the full least-squares solution instead of the N_c SVD channels.
    """
    u = np.asarray(u, dtype=float)
    x = np.broadcast_to(np.asarray(x, dtype=float), u.shape)
    un = _norm(u, params["u_center"], params["u_scale"])
    xn = _norm(x, params["x_center"], params["x_scale"])
    m, dp = int(params["m"]), int(params["degree"]) + 1
    if full:
        f, r = _filtered(params, un, xn)
        th = np.asarray(params["theta"]).reshape(m, dp, -1)
        return np.einsum("tis,ta,ias->t", f, r, th)
    g = input_basis(un, params["powers"], params["harmonics"])
    r = poly_basis(xn, params["degree"])
    y = np.zeros(u.size)
    for ch in params["channels_fit"]:
        eta = np.asarray(ch["eta"])  # (n, d+1)
        xi = np.asarray(ch["xi"])    # (m, d+1)
        nl = np.einsum("tj,tb,jb->t", g, r, eta)
        lf = laguerre_filter(nl, m, params["q"], params["T"])
        y += np.einsum("ti,ta,ia->t", lf, r, xi)
    return y


def _positions(rec, p) -> np.ndarray:
    if p["position_source"] == "x2":
        return np.asarray(rec.x2, dtype=float)
    return float(p["x_per_volt"]) * np.asarray(rec.u2, dtype=float)


def fit(recordings, options) -> dict:
    """Fit to recordings with columns ``u2`` (other axis' drive [V]), ``y`` [um], ``x2`` [um].

    Parameters
    ----------
    recordings : sequence of Recording
    options : Options or mapping
        ``hammerstein_*`` options (see :func:`add_options`); missing ones take
        :data:`DEFAULTS`.

    Returns
    -------
    dict
        Parameters (see :func:`fit_arrays`) plus ``position_source`` ("x2" or "u2"),
        ``x_per_volt`` and ``x_default`` [um] (mean training position, used by
        :func:`simulate` when it gets no positions).
    """
    from .common import IdentError

    if any(getattr(r, "u2", None) is None for r in recordings):
        raise IdentError("hammerstein: every recording needs the other axis' drive (column u2)")
    src = _opt(options, "position")
    if src == "auto":
        src = "x2" if all(getattr(r, "x2", None) is not None for r in recordings) else "u2"
    if src == "x2" and any(getattr(r, "x2", None) is None for r in recordings):
        raise IdentError("hammerstein: --hammerstein-position x2 needs column x2 in every recording")
    settings = {k: _opt(options, k) for k in ("m", "q", "T", "degree", "powers", "harmonics",
                                              "channels", "rcond", "refine")}
    p0 = {"position_source": src, "x_per_volt": float(_opt(options, "x_per_volt"))}
    xs = [_positions(r, p0) for r in recordings]
    try:
        params = fit_arrays([r.u2 for r in recordings], xs, [r.y for r in recordings], **settings)
    except ValueError as exc:
        raise IdentError(str(exc)) from None
    params.update(p0)
    params["x_default"] = float(np.mean(np.concatenate(xs)))
    return params


def simulate(params: dict, t, u, u2=None, x2=None) -> np.ndarray:
    """Coupled displacement y [um] of this axis.

    Parameters
    ----------
    params : dict
        From :func:`fit`.
    t : array_like
        Sample times [s] (unused: the Laguerre filters run per sample).
    u : array_like
        This axis' drive [V] (unused: the model is driven by ``u2``).
    u2 : array_like
        Other axis' drive [V]; required.
    x2 : array_like, optional
        Other axis' position [um]. When absent: ``x_per_volt * u2`` if the model
        was fitted with ``position_source == "u2"``, else the mean training
        position ``x_default`` (a fallback: the position dependence is lost).
    """
    if u2 is None:
        raise ValueError("hammerstein: simulate needs the other axis' drive u2")
    u2 = np.asarray(u2, dtype=float)
    if x2 is not None:
        x = np.asarray(x2, dtype=float)
    elif params.get("position_source") == "u2":
        x = float(params["x_per_volt"]) * u2
    else:
        x = np.full(u2.shape, float(params.get("x_default", params["x_center"])))
    return predict(params, u2, x)
