"""Helpers shared by the model kinds: normalization, fit metrics, linear fits.

Every model kind in piezoctl is linear in its weights once the operator
outputs are known (KP, RKP, EUPI, Preisach). A fit therefore stacks, per
recording, a feature matrix computed on every sample, adds offset columns,
and solves a (possibly bounded) least-squares problem. :func:`solve_linear`
does this through the normal equations accumulated block by block, so memory
stays bounded however long the recordings are.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from ..errors import CliError

__all__ = [
    "Options", "IdentError", "nrmse", "rmse", "drive_range", "normalize", "fit_stride",
    "solve_linear", "LinearFit", "Gram", "add_common_options", "COMMON_OPTION_DESTS", "recording_rows",
    "offset_params",
]


class IdentError(CliError):
    """Identification cannot proceed (bad option, data that cannot identify the model)."""


class Options(dict):
    """Options of a fit: a dict whose keys also read as attributes.

    ``options["kp_levels"]`` and ``options.kp_levels`` are the same value;
    a missing attribute raises :class:`AttributeError`.
    """

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name: str, value: Any) -> None:
        self[name] = value


# Options every kind receives (identify registers them once; see docs/identification.md).
COMMON_OPTION_DESTS = ("u_range", "offset", "max_fit_rows")


def add_common_options(parser) -> None:
    """Register the options shared by all kinds on an ``identify``-like parser."""
    parser.add_argument("--u-range", nargs=2, type=float, metavar=("UMIN", "UMAX"), default=None,
                        help="drive range [V] mapped to the normalized input [-1, 1] "
                             "(default: min and max of u over all data files)")
    parser.add_argument("--offset", choices=("shared", "per-file"), default="shared",
                        help="output offset: one for all files (default), or one fitted per data "
                             "file (for recordings from different sessions; the model keeps their mean)")
    parser.add_argument("--max-fit-rows", type=int, default=200_000, metavar="N",
                        help="at most N samples (evenly strided over all files) enter the least "
                             "squares; operator states are always computed on every sample "
                             "(default 200000)")


def rmse(y: np.ndarray, yhat: np.ndarray) -> float:
    """Root-mean-square error [unit of y]."""
    y = np.asarray(y, dtype=np.float64)
    return float(np.sqrt(np.mean((np.asarray(yhat, dtype=np.float64) - y) ** 2)))


def nrmse(y: np.ndarray, yhat: np.ndarray) -> float:
    """Normalized RMS error: RMS(yhat - y) / (max(y) - min(y)) [dimensionless].

    Returns inf when y is constant.
    """
    y = np.asarray(y, dtype=np.float64)
    span = float(np.max(y) - np.min(y))
    e = rmse(y, yhat)
    return e / span if span > 0 else float("inf")


def drive_range(recordings: Sequence, u_range: Sequence[float] | None = None) -> tuple[float, float]:
    """Drive range [V] of the normalization: ``u_range`` if given, else the data's min and max.

    Raises
    ------
    IdentError
        An empty or inverted range.
    """
    if u_range is not None:
        lo, hi = float(u_range[0]), float(u_range[1])
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise IdentError(f"--u-range {lo:g} {hi:g}: UMAX must be greater than UMIN")
        return lo, hi
    lo = min(float(np.min(r.u)) for r in recordings)
    hi = max(float(np.max(r.u)) for r in recordings)
    if not hi > lo:
        raise IdentError(f"the drive u is constant ({lo:g} V) in all data files: nothing to identify "
                         "(give --u-range if this is intended)")
    return lo, hi


def normalize(u: np.ndarray, u_min: float, u_max: float) -> np.ndarray:
    """Map drive [V] to the normalized input: u_min -> -1, u_max -> +1 (not clipped)."""
    mid = 0.5 * (u_min + u_max)
    half = 0.5 * (u_max - u_min)
    return (np.asarray(u, dtype=np.float64) - mid) / half


def recording_rows(recordings: Sequence) -> list[int]:
    """Number of samples of each recording."""
    return [len(r.t) for r in recordings]


def fit_stride(total_rows: int, max_rows: int) -> int:
    """Row stride so that at most ``max_rows`` of ``total_rows`` samples enter a fit."""
    if max_rows < 1:
        raise IdentError(f"--max-fit-rows {max_rows}: must be at least 1")
    return max(1, -(-int(total_rows) // int(max_rows)))


class LinearFit:
    """Result of :func:`solve_linear`.

    Attributes
    ----------
    coef : ndarray, shape (P,)
        Weights of the feature columns.
    offsets : ndarray, shape (F,)
        Output offset of each file [unit of y] (all equal when shared).
    offset : float
        The offset a model keeps: the shared one, or the mean of per-file ones.
    rows : int
        Samples that entered the fit.
    """

    def __init__(self, coef, offsets, rows):
        self.coef = np.asarray(coef, dtype=np.float64)
        self.offsets = np.asarray(offsets, dtype=np.float64)
        self.offset = float(np.mean(self.offsets))
        self.rows = int(rows)


class Gram:
    """Normal equations ``A^T A``, ``A^T y`` of a stacked least-squares problem.

    Attributes
    ----------
    G : ndarray, shape (P + n_off, P + n_off)
        Gram matrix; the feature columns first, then the offset columns.
    b : ndarray, shape (P + n_off,)
        ``A^T y``.
    P : int
        Number of feature columns.
    n_off : int
        Number of offset columns (0, 1, or one per file).
    offset : str
        ``"shared"``, ``"per-file"`` or ``"none"``.
    n_files : int
        Number of files.
    rows : int
        Samples accumulated.
    """

    def __init__(self, features, targets, offset="shared", max_rows=200_000, block=16384):
        nf = len(features)
        if nf != len(targets) or nf == 0:
            raise ValueError("features and targets must be non-empty sequences of equal length")
        if offset not in ("shared", "per-file", "none"):
            raise IdentError(f"--offset {offset}: must be shared or per-file")
        lengths = [len(t) for t in targets]
        stride = fit_stride(sum(lengths), max_rows)
        n_off = {"shared": 1, "per-file": nf, "none": 0}[offset]
        P = None
        G = b = None
        rows = 0
        for f, (X, y) in enumerate(zip(features, targets)):
            idx = np.arange(0, lengths[f], stride)
            for s in range(0, idx.size, block):
                sel = idx[s:s + block]
                Xb = X(sel) if callable(X) else X[sel]
                Xb = np.asarray(Xb, dtype=np.float64)
                if P is None:
                    P = Xb.shape[1]
                    G = np.zeros((P + n_off, P + n_off))
                    b = np.zeros(P + n_off)
                if n_off:
                    ones = np.zeros((sel.size, n_off))
                    ones[:, 0 if offset == "shared" else f] = 1.0
                    Xb = np.hstack([Xb, ones])
                yb = np.asarray(y, dtype=np.float64)[sel]
                G += Xb.T @ Xb
                b += Xb.T @ yb
                rows += sel.size
        self.G, self.b, self.P, self.n_off = G, b, P, n_off
        self.offset, self.n_files, self.rows = offset, nf, rows

    def solve(self, cols=None, lower=-np.inf, upper=np.inf, ridge=0.0, penalty=None) -> LinearFit:
        """Bounded least squares on a subset ``cols`` of the feature columns (default all).

        ``lower``, ``upper``, ``penalty`` refer to the selected columns; see
        :func:`solve_linear` for ``ridge`` and ``penalty``.
        """
        P = self.P
        cols = np.arange(P) if cols is None else np.asarray(cols, dtype=int)
        p = cols.size
        sel = np.concatenate([cols, P + np.arange(self.n_off)])
        G = self.G[np.ix_(sel, sel)].copy()
        b = self.b[sel]
        scale = float(np.mean(np.diag(G)[:p])) if p else 0.0
        if ridge > 0 and p:
            G[:p, :p] += np.eye(p) * ridge * scale
        if penalty is not None:
            G[:p, :p] += np.asarray(penalty, dtype=np.float64) * scale
        # Column scaling keeps the factorization well conditioned.
        d = np.sqrt(np.maximum(np.diag(G), 1e-300))
        Gs = G / d[:, None] / d[None, :]
        bs = b / d
        jitter = 1e-12 * float(np.trace(Gs)) / Gs.shape[0]
        from scipy import linalg, optimize  # here: importing ident.common stays light (piezoctl --help)
        R = linalg.cholesky(Gs + jitter * np.eye(Gs.shape[0]), lower=False)
        z = linalg.solve_triangular(R, bs, trans="T")
        lo = np.concatenate([np.broadcast_to(np.asarray(lower, dtype=float), (p,)),
                             np.full(self.n_off, -np.inf)])
        hi = np.concatenate([np.broadcast_to(np.asarray(upper, dtype=float), (p,)),
                             np.full(self.n_off, np.inf)])
        if np.all(np.isinf(lo)) and np.all(np.isinf(hi)):
            xs = linalg.solve_triangular(R, z)
        else:
            res = optimize.lsq_linear(R, z, bounds=(lo * d, hi * d), method="bvls", tol=1e-12)
            xs = res.x
        x = xs / d
        if self.offset == "shared":
            offs = np.full(self.n_files, x[p])
        elif self.offset == "per-file":
            offs = x[p:]
        else:
            offs = np.zeros(self.n_files)
        out = LinearFit(x[:p], offs, self.rows)
        # |A x - y|^2 = |R x - z|^2 - |z|^2 + |y|^2; z depends on the columns chosen,
        # so subsets compare by |R x - z|^2 - |z|^2 (same |y|^2 for all)
        out.cost = float(np.sum((R @ xs - z) ** 2) - np.sum(z ** 2))
        return out


def solve_linear(features: Sequence[np.ndarray], targets: Sequence[np.ndarray], *,
                 lower: np.ndarray | float = -np.inf, upper: np.ndarray | float = np.inf,
                 offset: str = "shared", max_rows: int = 200_000, ridge: float = 0.0,
                 penalty: np.ndarray | None = None, block: int = 16384) -> LinearFit:
    """Least squares ``y_f ~ X_f @ coef + c_f`` over files f, with bounds on ``coef``.

    Parameters
    ----------
    features : sequence of ndarray, shape (T_f, P), or callables
        Feature matrix of each file (every sample). A callable ``g(rows)``
        returning the matrix for an index array avoids materializing columns
        that are built on the fly (e.g. Kronecker products).
    targets : sequence of ndarray, shape (T_f,)
        Measured output of each file [um].
    lower, upper : float or ndarray, shape (P,)
        Bounds on the weights (the offsets are free).
    offset : {"shared", "per-file", "none"}
        One offset for all files, one per file, or none.
    max_rows : int
        At most this many samples enter the fit, evenly strided over all files.
    ridge : float
        Tikhonov weight, relative to the mean diagonal of the Gram matrix of the
        features (0: none). Offsets are not penalized.
    penalty : ndarray, shape (P, P), optional
        A further quadratic penalty ``coef^T K coef`` (e.g. ``D^T D`` of a
        difference operator), scaled like ``ridge`` by the mean diagonal of the
        Gram matrix of the features.
    block : int
        Rows per block of the Gram accumulation.

    Returns
    -------
    LinearFit

    Notes
    -----
    The Gram matrix ``A^T A`` and ``A^T y`` are accumulated in blocks
    (:class:`Gram`), then factored ``A^T A = R^T R`` (Cholesky, with a
    relative jitter of 1e-12 for rank deficiency); ``|A x - y|^2 = |R x - z|^2
    + const`` with ``R^T z = A^T y``, so the bounded problem is solved on the
    P x P system by :func:`scipy.optimize.lsq_linear` (bounded-variable least
    squares).
    """
    gram = Gram(features, targets, offset=offset, max_rows=max_rows, block=block)
    return gram.solve(lower=lower, upper=upper, ridge=ridge, penalty=penalty)


def offset_params(res: LinearFit, options) -> dict:
    """Output-offset entries of a model's parameters from its linear fit.

    Parameters
    ----------
    res : LinearFit
        The fit, its offsets in the model's output unit [um].
    options : mapping
        The fit's options; ``offset`` is the common ``--offset``.

    Returns
    -------
    dict
        ``offset`` [um], the offset the model keeps (:attr:`LinearFit.offset`),
        and with ``--offset per-file`` also ``offsets_per_file`` [um], one per
        data file in their order (what :func:`simulate_offsets` reads back).
    """
    out = {"offset": res.offset}
    if options.get("offset") == "per-file":
        out["offsets_per_file"] = res.offsets
    return out


def simulate_offsets(params: dict, n_files: int) -> list[float]:
    """Per-file offsets stored in ``params`` (``offsets_per_file``), else the shared one."""
    per = params.get("offsets_per_file")
    if per and len(per) == n_files:
        return [float(v) for v in per]
    return [float(params.get("offset", 0.0))] * n_files


def check_positive_int(name: str, value: int, minimum: int = 1) -> int:
    """Return ``value`` as int, or raise :class:`IdentError` naming the option."""
    if int(value) != value or value < minimum:
        raise IdentError(f"{name} {value}: must be an integer >= {minimum}")
    return int(value)


def as_callable(fn: Callable | np.ndarray):
    """Feature source as a callable of row indices."""
    return fn if callable(fn) else (lambda rows: fn[rows])
