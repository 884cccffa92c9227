"""Rate-independent hysteresis laws of the foreign stage (docs/foreign-stage.md).

Written independently of the project's own stage model. Every law maps a normalized
drive ``v`` (dimensionless; ``v = (u - 75 V) / 75 V``, so 0..150 V is -1..1) to a
normalized output ``h`` whose major loop over ``v`` in [-1, 1] spans exactly [-1, 1]; the
stage scales ``h`` to micrometres. Each law starts from negative saturation (the drive
came from ``v = -1.5``). Laws are defined for ``v`` in [-1.5, 1.5]; outside it the drive
is clipped.

All laws run over a whole drive array at once. The drive is split into monotone runs;
within a run every law has a closed form or a running maximum, so Python loops run over
runs (turning points), not samples.

Laws: :class:`Preisach` (random smooth Everett function), :class:`MaxwellSlip`,
:class:`ColemanHodgdon` (Duhem), :class:`KrasnoselskiiPokrovskii`,
:class:`GeneralizedPI` (asymmetric envelope) and :class:`BoucWen` (exponent n != 1).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

__all__ = ["Law", "Preisach", "MaxwellSlip", "ColemanHodgdon", "KrasnoselskiiPokrovskii",
           "GeneralizedPI", "BoucWen", "LAWS", "draw_law", "monotone_runs", "loop_width"]

V_LIM = 1.5          # normalized drive domain of every law [-V_LIM, V_LIM]
_CHUNK = 16384        # samples per block inside one long monotone run (bounds memory)


def monotone_runs(v: np.ndarray) -> list[tuple[int, int, int]]:
    """Split a drive into monotone runs.

    Parameters
    ----------
    v : ndarray, shape (T,)
        Drive (any unit).

    Returns
    -------
    list of (start, end, direction)
        Sample indices, inclusive at both ends (consecutive runs share their turning
        sample), and +1 (non-decreasing) or -1 (non-increasing). Flat stretches belong
        to the run before them (to the first run: ascending).
    """
    v = np.asarray(v, dtype=float)
    if v.size < 2:
        return []
    s = np.sign(np.diff(v))
    nz = np.nonzero(s)[0]
    if nz.size == 0:
        return [(0, v.size - 1, 1)]
    # forward fill the zeros (leading zeros take the first nonzero direction)
    idx = np.where(s != 0, np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    s = s[idx]
    s[:nz[0]] = s[nz[0]]
    brk = np.nonzero(s[1:] != s[:-1])[0] + 1
    b = np.concatenate(([0], brk, [v.size - 1]))
    return [(int(b[k]), int(b[k + 1]), int(s[b[k]])) for k in range(b.size - 1)]


def loop_width(law, n: int = 2001) -> float:
    """Largest vertical width of the major loop (normalized output; stroke is 2).

    Parameters
    ----------
    law : Law
        A normalized law.
    n : int
        Samples per branch.
    """
    up = np.linspace(-1, 1, n)
    path = np.concatenate((up, up[::-1], up, up[::-1]))
    h = law(path)
    asc, desc = h[2 * n:3 * n], h[3 * n:][::-1]
    return float(np.max(np.abs(desc - asc)))


class Law:
    """A rate-independent hysteresis law ``h = H[v]`` (normalized, see the module doc).

    Subclasses implement :meth:`draw` and :meth:`_raw`; :meth:`__call__` prepends the
    saturated start, clips the drive to the domain and applies the normalization.
    """

    name = "law"
    return_point_memory = True
    rate_capable = False     # accepts a per-sample width factor (rate-dependent option)

    scale = 1.0
    shift = 0.0

    @classmethod
    def draw(cls, rng: np.random.Generator) -> "Law":
        """A law with random parameters (ranges in docs/foreign-stage.md), normalized and
        with a major-loop width of 4 to 20 % of the stroke."""
        for _ in range(200):
            law = cls._draw(rng)
            law._normalize()
            if 0.08 <= loop_width(law) <= 0.40:
                return law
        raise RuntimeError(f"{cls.__name__}: no draw with a realistic loop width")

    @classmethod
    def _draw(cls, rng):
        raise NotImplementedError

    def _raw(self, v, width=None):
        raise NotImplementedError

    def _normalize(self) -> None:
        self.scale, self.shift = 1.0, 0.0
        up = np.linspace(-1, 1, 1001)
        h = self(np.concatenate((up, up[::-1], up, up[::-1])))[2002:]
        lo, hi = float(h.min()), float(h.max())
        self.scale = 2.0 / (hi - lo)
        self.shift = -1.0 - lo * self.scale

    def __call__(self, v, width=None) -> np.ndarray:
        """Output over a whole drive.

        Parameters
        ----------
        v : array_like, shape (T,)
            Normalized drive (dimensionless), clipped to [-1.5, 1.5].
        width : array_like, shape (T,), optional
            Per-sample factor (>= 1) on the loop width; only laws with
            ``rate_capable`` accept it.

        Returns
        -------
        ndarray, shape (T,)
            Normalized output (major loop on [-1, 1] spans [-1, 1]).
        """
        v = np.clip(np.asarray(v, dtype=float), -V_LIM, V_LIM)
        v = np.concatenate(([-V_LIM], v))
        if width is not None:
            if not self.rate_capable:
                raise ValueError(f"{self.name}: no rate-dependent width")
            width = np.concatenate(([1.0], np.asarray(width, dtype=float)))
        return self._raw(v, width)[1:] * self.scale + self.shift

    def describe(self) -> str:
        """Name and parameters in one line."""
        return self.name


# --------------------------------------------------------------------------- elements
class _Elements(Law):
    """Sum of elements, each a state ``p`` pushed by an ascending edge ``up(v)`` and a
    descending edge ``dn(v)`` (``up <= dn``): ascending ``p = max(p, up(v))``,
    descending ``p = min(p, dn(v))``. Plays, generalized plays, elasto-slide elements
    and KP kernels are all of this kind; so the output obeys return-point memory."""

    rate_capable = True
    weights: np.ndarray
    linear: float = 0.0

    def _edges(self, v, w):
        """(up, dn), each shape (len(v), P), for drive v and width factor w (or None)."""
        raise NotImplementedError

    def _init_state(self):
        up, dn = self._edges(np.array([-V_LIM]), None)
        return dn[0].copy()          # the drive came down to -V_LIM

    def _raw(self, v, width=None):
        out = np.empty(v.size)
        p = self._init_state()
        out[0] = p @ self.weights + self.linear * v[0]
        for s, e, d in monotone_runs(v):
            for a in range(s + 1, e + 1, _CHUNK):
                b = min(a + _CHUNK, e + 1)
                up, dn = self._edges(v[a:b], None if width is None else width[a:b])
                if d > 0:
                    q = np.maximum.accumulate(np.vstack((p[None, :], up)), axis=0)[1:]
                    q = np.minimum(q, dn)
                else:
                    q = np.minimum.accumulate(np.vstack((p[None, :], dn)), axis=0)[1:]
                    q = np.maximum(q, up)
                out[a:b] = q @ self.weights + self.linear * v[a:b]
                p = q[-1]
        return out


def _positive_profile(rng, n, decay):
    """Random positive weights over n elements, decaying on average (dimensionless)."""
    base = np.exp(-decay * np.linspace(0, 1, n))
    return base * rng.uniform(0.3, 1.0, n)


class GeneralizedPI(_Elements):
    """Generalized Prandtl-Ishlinskii: plays with a nonlinear, asymmetric envelope.

    Ascending edge ``g_up(v) - r_j``, descending edge ``g_dn(v) + r_j``, where
    ``g(v) = v + a (v^2 - 1) / 2 + b (v^3 - v) / 3`` with different (a, b) up and down,
    both increasing on the domain. 8 to 24 plays, radii from r_min to 0.25..0.9 (drive
    units), weights decaying, plus a linear part of 0.2 to 0.6 of the plays' weight.
    """

    name = "generalized_pi"

    @classmethod
    def _draw(cls, rng):
        self = cls()
        while True:
            self.cu = rng.uniform([-0.4, -0.25], [0.4, 0.25])
            self.cd = rng.uniform([-0.4, -0.25], [0.4, 0.25])
            x = np.linspace(-V_LIM, V_LIM, 301)
            if all(np.min(1 + c[0] * x + c[1] * (x * x - 1 / 3)) > 0.2 for c in (self.cu, self.cd)):
                break
        x = np.linspace(-V_LIM, V_LIM, 301)
        gap = np.max(np.abs(self._g(x, self.cu) - self._g(x, self.cd)))
        n = int(rng.integers(8, 25))
        rmax = rng.uniform(0.1, 0.5)
        self.r = np.linspace(0.5 * gap + 1e-3, 0.5 * gap + rmax, n)
        self.weights = _positive_profile(rng, n, rng.uniform(0.5, 3.0))
        self.linear = rng.uniform(0.2, 0.6) * self.weights.sum()
        return self

    @staticmethod
    def _g(v, c):
        return v + c[0] * (v * v - 1) / 2 + c[1] * (v ** 3 - v) / 3

    def _edges(self, v, w):
        r = self.r[None, :] if w is None else self.r[None, :] * w[:, None]
        return self._g(v, self.cu)[:, None] - r, self._g(v, self.cd)[:, None] + r

    def describe(self):
        return (f"generalized PI, {self.r.size} plays, r {self.r[0]:.2f}..{self.r[-1]:.2f}, "
                f"envelope up {self.cu.round(2).tolist()} down {self.cd.round(2).tolist()}")


class MaxwellSlip(_Elements):
    """Maxwell slip: 3 to 10 elasto-slide elements (stiffness k_i, slip force f_i) in
    parallel with the piezo's elastic path; the element deflection is ``v - play_{f_i/k_i}(v)``
    and the output is ``c v - sum k_i (v - play_i)``. Stiffness log-uniform over a decade,
    slip deflection 0.02..0.5 (drive units)."""

    name = "maxwell_slip"

    @classmethod
    def _draw(cls, rng):
        self = cls()
        n = int(rng.integers(3, 11))
        k = np.exp(rng.uniform(0, np.log(10), n))
        self.r = np.sort(rng.uniform(0.02, 0.5, n))
        frac = rng.uniform(0.15, 0.6)                 # hysteretic share of the stiffness
        k = k / k.sum() * frac
        self.weights = k                               # + sum k_i play_i
        self.linear = 1.0 - k.sum()                    # c v - sum k_i v
        return self

    def _edges(self, v, w):
        r = self.r[None, :] if w is None else self.r[None, :] * w[:, None]
        return v[:, None] - r, v[:, None] + r

    def describe(self):
        return f"Maxwell slip, {self.r.size} elements, slip {self.r.min():.2f}..{self.r.max():.2f}"


class KrasnoselskiiPokrovskii(_Elements):
    """KP operator: ramp kernels on a grid of thresholds (beta < alpha) with a random
    smooth positive density (2 to 4 Gaussian bumps in centre/half-width coordinates over a
    floor), ramp width a, plus a linear part of 0.3 to 1.0 (kernels span 2 in total)."""

    name = "kp"

    @classmethod
    def _draw(cls, rng):
        self = cls()
        n = int(rng.integers(10, 17))
        lv = np.linspace(-1.2, 1.2, n)
        self.a = (lv[1] - lv[0]) * rng.uniform(0.8, 1.0)
        al, be = np.meshgrid(lv, lv, indexing="ij")
        keep = al - be >= self.a - 1e-12
        self.alpha, self.beta = al[keep], be[keep]
        c, r = (self.alpha + self.beta) / 2, (self.alpha - self.beta) / 2
        mu = 0.05 + np.zeros_like(c)
        for _ in range(int(rng.integers(2, 5))):
            c0, r0 = rng.uniform(-0.8, 0.8), rng.uniform(0.0, 0.3)
            sc, sr = rng.uniform(0.2, 0.8), rng.uniform(0.05, 0.25)
            mu += rng.uniform(0.3, 1.0) * np.exp(-0.5 * ((c - c0) / sc) ** 2 - 0.5 * ((r - r0) / sr) ** 2)
        self.weights = mu / mu.sum()
        self.linear = rng.uniform(0.3, 1.0)
        return self

    def _edges(self, v, w):
        a = self.a if w is None else self.a * w[:, None]
        up = -1 + 2 * np.clip((v[:, None] - self.alpha[None, :] + a) / a, 0, 1)
        dn = -1 + 2 * np.clip((v[:, None] - self.beta[None, :]) / a, 0, 1)
        if w is not None:   # a wider ramp must not cross the other edge
            up = np.minimum(up, dn)
        return up, dn

    def describe(self):
        return f"KP, {self.alpha.size} kernels, ramp {self.a:.3f}"


# --------------------------------------------------------------------------- Preisach
class Preisach(Law):
    """Classical Preisach model (relays +-1) with a random smooth positive density
    mu(alpha, beta) on alpha >= beta: 2 to 5 Gaussian bumps in centre/half-width
    coordinates (centre -0.8..0.8, half-width 0..0.25), a ridge near the diagonal (decay 0.02..0.15)
    and a floor, plus a linear part of 0.5 to 1.5 times the relays' total weight. The Everett
    function is tabulated on a 241-point grid and interpolated bilinearly; the output
    follows the stack of dominant extrema (exact wiping-out and return-point memory)."""

    name = "preisach"
    N = 241

    @classmethod
    def _draw(cls, rng):
        self = cls()
        x = np.linspace(-V_LIM, V_LIM, cls.N)
        self.dx = x[1] - x[0]
        A, B = np.meshgrid(x, x, indexing="ij")
        c, r = (A + B) / 2, np.maximum((A - B) / 2, 0)
        mu = 0.02 + 0.3 * rng.uniform(0.2, 1.0) * np.exp(-r / rng.uniform(0.02, 0.15))
        for _ in range(int(rng.integers(2, 6))):
            c0, r0 = rng.uniform(-0.8, 0.8), rng.uniform(0.0, 0.25)
            sc, sr = rng.uniform(0.2, 0.9), rng.uniform(0.05, 0.25)
            mu = mu + rng.uniform(0.2, 1.0) * np.exp(-0.5 * ((c - c0) / sc) ** 2 - 0.5 * ((r - r0) / sr) ** 2)
        mu = np.where(A >= B, mu, 0.0) * self.dx ** 2
        # E[i, j] = sum over a <= x_i, b >= x_j of mu (mu is zero for b > a)
        self.E = np.cumsum(np.cumsum(mu[:, ::-1], axis=1)[:, ::-1], axis=0)
        self.linear = rng.uniform(0.5, 1.5) * self.E[-1, 0]
        return self

    def _ev(self, a, b):
        """Everett function at (a, b) arrays, bilinear."""
        ia = (np.asarray(a, dtype=float) + V_LIM) / self.dx
        ib = (np.asarray(b, dtype=float) + V_LIM) / self.dx
        return map_coordinates(self.E, np.vstack((np.ravel(ia), np.ravel(ib))), order=1, mode="nearest")

    def _raw(self, v, width=None):
        etot = float(self.E[-1, 0])
        stack = [(V_LIM, etot), (-V_LIM, -etot)]     # alternating max, min; top = anchor
        n = v.size
        anc_v = np.empty(n)
        anc_y = np.empty(n)
        sgn = np.empty(n)
        anc_v[0], anc_y[0], sgn[0] = -V_LIM, -etot, 1.0
        for s, e, d in monotone_runs(v):
            i = s + 1
            seg = v[s + 1:e + 1]
            pos = 0
            while pos < seg.size:
                thr = stack[-2][0]
                if d > 0:
                    k = int(np.searchsorted(seg[pos:], thr, side="right"))
                else:
                    k = int(np.searchsorted(-seg[pos:], -thr, side="right"))
                a, b = i + pos, i + pos + k
                anc_v[a:b], anc_y[a:b], sgn[a:b] = stack[-1][0], stack[-1][1], d
                pos += k
                if pos < seg.size:
                    stack.pop()
                    stack.pop()
            ve = v[e]
            m, ym = stack[-1]
            ye = ym + 2 * float(self._ev(ve, m)[0]) if d > 0 else ym - 2 * float(self._ev(m, ve)[0])
            stack.append((ve, ye))
        up = sgn > 0
        a_arg = np.where(up, v, anc_v)
        b_arg = np.where(up, anc_v, v)
        y = anc_y + 2 * sgn * self._ev(a_arg, b_arg)
        return y + self.linear * v

    def describe(self):
        return "Preisach, random smooth Everett function"


# --------------------------------------------------------------------------- Duhem
class ColemanHodgdon(Law):
    """Duhem model of Coleman-Hodgdon type: ``dh/dv = alpha sign(dv) (f(v) - h) + g(v)``
    with anhysteretic ``f(v) = v + c3 v^3`` and ``g = gamma f'`` (alpha 1.5..6, gamma
    0.6..0.9, c3 -0.15..0.3). Linear in h, so each monotone run has a closed form from a
    tabulated integral. No return-point memory (minor loops drift)."""

    name = "coleman_hodgdon"
    return_point_memory = False

    @classmethod
    def _draw(cls, rng):
        self = cls()
        self.alpha = rng.uniform(1.5, 6.0)
        self.gamma = rng.uniform(0.6, 0.9)
        self.c3 = rng.uniform(-0.15, 0.3)
        self.x = np.linspace(-V_LIM, V_LIM, 6001)
        f = self.x + self.c3 * self.x ** 3
        g = self.gamma * (1 + 3 * self.c3 * self.x ** 2)
        self.P = {}
        for s in (1, -1):
            integrand = np.exp(s * self.alpha * self.x) * (s * self.alpha * f + g)
            self.P[s] = np.concatenate(([0.0], np.cumsum((integrand[1:] + integrand[:-1]) / 2 * np.diff(self.x))))
        return self

    def _branch(self, s, v0, h0, v):
        P = self.P[s]
        p0 = np.interp(v0, self.x, P)
        return np.exp(-s * self.alpha * v) * (np.exp(s * self.alpha * v0) * h0 + np.interp(v, self.x, P) - p0)

    def _raw(self, v, width=None):
        out = np.empty(v.size)
        out[0] = -V_LIM - self.c3 * V_LIM ** 3   # start on the anhysteretic curve at -V_LIM
        h = out[0]
        for s, e, d in monotone_runs(v):
            out[s + 1:e + 1] = self._branch(d, v[s], h, v[s + 1:e + 1])
            h = out[e]
        return out

    def describe(self):
        return f"Coleman-Hodgdon alpha={self.alpha:.2f} gamma={self.gamma:.2f} c3={self.c3:.2f}"


class BoucWen(Law):
    """Rate-independent Bouc-Wen: ``dz/dv = A - |z|^n (beta sign(z dv) + gamma)``, output
    ``v - kappa z / z_s`` (the piezo's hysteretic term subtracts from the linear one),
    exponent n in 0.5..0.85 or 1.3..3 (never 1), beta 0.5..2, gamma in (-beta, beta) / 2,
    kappa 0.3..0.9 of the largest value that keeps the output increasing. The flow in z is autonomous within a
    monotone run, so one tabulated solution and its inverse give every run in closed form."""

    name = "bouc_wen"
    return_point_memory = False

    @classmethod
    def _draw(cls, rng):
        self = cls()
        self.n = rng.uniform(0.5, 0.85) if rng.random() < 0.3 else rng.uniform(1.3, 3.0)
        self.beta = rng.uniform(0.5, 2.0)
        self.gamma = rng.uniform(-0.5, 0.5) * self.beta
        self.A = 1.0
        self.zs = (self.A / (self.beta + self.gamma)) ** (1 / self.n)
        max_slope = self.A + self.zs ** self.n * (self.beta - self.gamma)   # dz/dv right after a reversal
        self.kappa = rng.uniform(0.3, 0.9) * self.zs / max_slope
        # F(s): solution of dz/ds = A - |z|^n (beta sign z + gamma), F(0) = -zs (descending limit)
        ns, smax = 40001, 4.0
        h = smax / (ns - 1)
        A, n, be, ga = self.A, float(self.n), float(self.beta), float(self.gamma)

        def g(z):
            return A - abs(z) ** n * ((be if z > 0 else -be if z < 0 else 0.0) + ga)
        F = np.empty(ns)
        z = -float(self.zs) * (1 - 1e-9)
        for k in range(ns):                       # RK4 on a scalar, once per law (0.2 s)
            F[k] = z
            k1 = g(z); k2 = g(z + h / 2 * k1); k3 = g(z + h / 2 * k2); k4 = g(z + h * k3)
            z = min(z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), self.zs)
        self.F = np.maximum.accumulate(F)
        self.s = np.linspace(0, smax, ns)
        return self

    def _flow(self, z0, ds):
        s0 = np.interp(z0, self.F, self.s)
        return np.interp(s0 + ds, self.s, self.F)

    def _raw(self, v, width=None):
        z = np.empty(v.size)
        z[0] = -self.zs
        for s, e, d in monotone_runs(v):
            seg = v[s + 1:e + 1]
            if d > 0:
                z[s + 1:e + 1] = self._flow(z[s], seg - v[s])
            else:
                z[s + 1:e + 1] = -self._flow(-z[s], v[s] - seg)
        return v - self.kappa * z / self.zs

    def describe(self):
        return f"Bouc-Wen n={self.n:.2f} beta={self.beta:.2f} gamma={self.gamma:.2f}"


LAWS = {cls.name: cls for cls in (Preisach, MaxwellSlip, ColemanHodgdon, KrasnoselskiiPokrovskii,
                                  GeneralizedPI, BoucWen)}


def draw_law(rng: np.random.Generator, name: str | None = None) -> Law:
    """A random law: the named one, or one of :data:`LAWS` drawn uniformly."""
    if name is None:
        name = list(LAWS)[int(rng.integers(len(LAWS)))]
    return LAWS[name].draw(rng)
