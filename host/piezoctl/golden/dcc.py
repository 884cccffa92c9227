"""Bit-exact golden model of ``firmware/core/dcc.c`` (KP compensation, DCC law).

See ``dcc.h`` and ``docs/kernels-kp.md``. :func:`quantize` turns the float
reference's parameters (``piezoctl.models.kp.dcc_law``) into the kernel's
coefficients and raises :class:`piezoctl.fixed.QOverflowError` when one does
not fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import fixed
from ..fixed import Q15, Q24
from ..models import kp as fkp
from ..models.kp import _runs
from . import kp as gkp
from .export import CHeader

__all__ = ["DCCQ", "check", "quantize", "comp_outputs_q", "dcc_process_q", "c_header",
           "error_report"]


@dataclass(frozen=True)
class DCCQ:
    """The C ``struct piezo_dcc_coeffs`` in integers."""

    grid: gkp.KPGridQ
    c: np.ndarray   # int64 (N,), q24: g * w_j
    g: int          # q24 gain, >= 1


def check(d: DCCQ) -> None:
    """Raise where ``piezo_dcc_init`` would refuse the coefficients."""
    gkp.check_grid(d.grid)
    if d.c.shape != (d.grid.N,):
        raise ValueError("c must have one entry per operator")
    if np.any(d.c < Q24.min) or np.any(d.c > Q24.max):
        raise fixed.QOverflowError("c outside q24")
    if not 1 <= d.g <= Q24.max:
        raise ValueError(f"gain g_q24 must be in 1..INT32_MAX, got {d.g}")


def quantize(grid: fkp.KPGrid, w, gain: float | None = None) -> DCCQ:
    """Kernel coefficients: ``c = q24(g w)``, ``g_q24 = q24(g)``, ``g = 1/sum(w)`` by default."""
    w = np.asarray(w, dtype=np.float64).ravel()
    g = fkp.dcc_gain(w) if gain is None else float(gain)
    d = DCCQ(grid=gkp.quantize_grid(grid), c=fixed.to_q(g * w, Q24), g=fixed.to_q(g, Q24))
    check(d)
    return d


def _ridge_o_plus(v, th, g: gkp.KPGridQ):
    x = v - th
    return (x - gkp.ridge_q(x, g)) + th


def comp_outputs_q(v_q15, g: gkp.KPGridQ) -> np.ndarray:
    """Compensation operators ``Psi`` (T, N) from reset for inputs ``v_q15``.

    Vectorized over monotone runs: within a run the formula depends only on
    ``v[k]`` and the constants of the last reversal, exactly as the kernel.
    """
    v = np.asarray(v_q15, dtype=np.int64).ravel()
    cpsi = np.full(g.N, g.nmin, dtype=np.int64)
    zo = cpsi.copy()
    xi, dr = g.nmin, -1
    out = np.empty((v.size, g.N), dtype=np.int64)
    for k0, k1, d in _runs(v, g.nmin):
        if d == 0:
            out[k0:k1] = cpsi
        else:
            if d != dr:
                xi = g.nmin if k0 == 0 else int(v[k0 - 1])
                zo = np.array(cpsi, copy=True)
                dr = d
            seg = v[k0:k1, None]
            lin = (seg - xi) + zo
            if d > 0:
                np.minimum(lin, _ridge_o_plus(seg, g.n2, g), out=out[k0:k1])
            else:
                np.maximum(lin, _ridge_o_plus(seg, g.n1, g), out=out[k0:k1])
        cpsi = out[k1 - 1]
    return out


def dcc_process_q(yd_q15, d: DCCQ) -> np.ndarray:
    """``piezo_dcc_process`` over a signal from reset: the drive ``u_q15`` (T,)."""
    g = d.grid
    yd = np.asarray(yd_q15, dtype=np.int64).ravel().tolist()
    cpsi = np.full(g.N, g.nmin, dtype=np.int64)
    zo = cpsi.copy()
    xi = vp = u_last = g.nmin
    dr = -1
    out = np.empty(len(yd), dtype=np.int64)
    for k, y in enumerate(yd):
        v = u_last
        if v != vp:
            dd = 1 if v > vp else -1
            if dd != dr:
                xi, zo, dr = vp, cpsi.copy(), dd
            lin = (v - xi) + zo
            if dd > 0:
                cpsi = np.minimum(lin, _ridge_o_plus(v, g.n2, g))
            else:
                cpsi = np.maximum(lin, _ridge_o_plus(v, g.n1, g))
            vp = v
        acc = int(cpsi @ d.c) + y * d.g
        u_last = fixed.sat_q15(fixed.rshift_rnd(acc, 24))
        out[k] = u_last
    return out


# ------------------------------------------------------------------ vectors

def std_model():
    """Reference DCC: the KP reference plane and density, g = 1/sum(w)."""
    grid, _, w, _ = gkp.std_grid()
    return grid, w


def edge_model() -> DCCQ:
    """Extreme coefficients: the edge grid, c at the q24 ends, the largest gain."""
    g, _ = gkp.edge_grid()
    c = np.array([Q24.max, Q24.min, 1 << 24, -(1 << 20), Q24.max, Q24.min, 5, -5,
                  1 << 28, -(1 << 27)], dtype=np.int64)
    d = DCCQ(grid=g, c=c, g=Q24.max)
    check(d)
    return d


def _realistic_yd(T: int, seed: int) -> np.ndarray:
    """A reachable desired output: the KP reference model driven by a realistic drive."""
    _, gs, _, ws = gkp.std_grid()
    return gkp.kp_process_q(gkp.realistic_signal(T, seed=seed), gs, ws)[0]


def c_header() -> str:
    h = CHeader("dcc")
    h.comment("DCC golden vectors: coefficients, desired outputs yd, drives u (q15).")
    grid, w = std_model()
    std = quantize(grid, w)
    half = quantize(grid, w, gain=0.5 / float(np.sum(w)))
    edge = edge_model()
    for name, d in (("dcc_std", std), ("dcc_half", half), ("dcc_edge", edge)):
        gkp.emit_grid(h, name, d.grid)
        h.define(f"{name}_G", d.g)
        h.array(f"{name}_c", "int32_t", d.c)
    cases = gkp.golden_cases()
    sig = dict(cases)
    sig["realistic"] = _realistic_yd(len(cases["realistic"]), seed=3)
    plan = [(name, "dcc_std", std) for name in sig]
    plan += [("realistic_half", "dcc_half", half), ("edges_edge", "dcc_edge", edge),
             ("random_edge", "dcc_edge", edge)]
    sig.update(realistic_half=sig["realistic"], edges_edge=cases["edges"],
               random_edge=cases["random"])
    for name, _, d in plan:
        h.array(f"dcc_case_{name}_yd", "int16_t", sig[name])
        h.array(f"dcc_case_{name}_u", "int16_t", dcc_process_q(sig[name], d))
    h.parts.append("#define DCC_GOLDEN_CASES(X) \\\n" + " \\\n".join(
        f"    X({name}, {set_})" for name, set_, _ in plan))
    # Inputs for the psi + Psi == v identity (the C test runs KP and DCC operators).
    for name in ("random", "alternating", "steps", "edges"):
        h.array(f"dcc_ops_{name}_v", "int16_t", cases[name])
    h.array("dcc_ops_realistic_v", "int16_t", gkp.realistic_signal(len(cases["random"]), seed=9))
    return str(h)


def error_report() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(case, u_float, u_fixed_q15): the DCC drive for a realistic desired output."""
    grid, w = std_model()
    d = quantize(grid, w)
    out = []
    for name, seed in (("realistic sweep 2 s", 11),):
        yd = _realistic_yd(20000, seed)
        uf = fkp.dcc_law(yd / Q15.one, grid, w)
        uq = dcc_process_q(yd, d)
        out.append((name, uf, uq))
    return out
