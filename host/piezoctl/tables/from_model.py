"""Coefficient tables from identified models (``piezoctl tables build``).

The firmware works in q15 full-scale units: drive ``u`` over the
controller's drive range and position ``r``, ``y`` over its position range
(:class:`Scale`, read from the controller's identity registers or given). A
model file is in volts and micrometres; this module maps it into those units,
quantizes it with the golden models' quantizers (exactly what the kernels
run), checks it as the firmware will at commit, and builds the image.

Kinds:

- ``eupi`` -> ``eupi_inverse``: the model's drive normalization must be the
  controller's drive range (identify with ``--u-range``), because unparallel
  play operators do not commute with an affine change of the input; the
  output side is linear: every weight scales by ``y_half / P_half`` and
  ``p0`` shifts.
- ``kp`` -> ``kp_dcc``: y = sum w_j psi_j + c1 v + c in micrometres becomes,
  in position FS, y = W' v - sum w'_j Psi_j + c' (psi_j + Psi_j = v) with
  W' = sum w'_j + c1', so the DCC law u = g (yd + Psi . w') with g = 1 / W'
  and yd = r - c' inverts it.

Both get the uncompensated straight line u = g r + o: the least-squares line
through the model's own response to a slow full-range sweep.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass

import numpy as np

from ..golden import dcc as gdcc
from ..models import kp as kpref
from ..models.eupi import eupi_inverse
from ..golden import eupi_inv as ginv
from ..ident import get_kind
from ..ident.eupi import to_params as eupi_to_params
from ..ident.kp import grid_of
from ..io.modelfile import Model
from ..models.eupi import EUPIParams, apply_kex, choose_kex, small_gain_margin
from .build import ctl_section, eupi_inverse_sections, kp_dcc_sections
from .image import TableImageError, build_image

__all__ = ["Scale", "Compiled", "compile_model", "table_from_model", "SUPPORTED_KINDS"]

SUPPORTED_KINDS = {"eupi": "eupi_inverse", "kp": "kp_dcc"}


@dataclass(frozen=True)
class Scale:
    """Physical values of q15 -1 and +1 (-32768 and +32768 LSB).

    Attributes
    ----------
    drive_min_v, drive_max_v : float
        Drive [V].
    position_min_um, position_max_um : float
        Position [um].
    """

    drive_min_v: float
    drive_max_v: float
    position_min_um: float
    position_max_um: float

    @property
    def p_mid(self) -> float:
        return 0.5 * (self.position_min_um + self.position_max_um)

    @property
    def p_half(self) -> float:
        return 0.5 * (self.position_max_um - self.position_min_um)

    def drive_to_fs(self, u):
        """Drive [V] -> normalized [-1, 1)."""
        return (np.asarray(u, dtype=np.float64) - self.drive_min_v) / (self.drive_max_v - self.drive_min_v) * 2 - 1

    def drive_from_fs(self, v):
        return self.drive_min_v + (np.asarray(v, dtype=np.float64) + 1) * 0.5 * (self.drive_max_v - self.drive_min_v)

    def position_to_fs(self, y):
        return (np.asarray(y, dtype=np.float64) - self.p_mid) / self.p_half

    def position_from_fs(self, r):
        return self.p_mid + np.asarray(r, dtype=np.float64) * self.p_half

    def to_dict(self) -> dict:
        return {"drive_min_v": self.drive_min_v, "drive_max_v": self.drive_max_v,
                "position_min_um": self.position_min_um, "position_max_um": self.position_max_um}


def _check_drive_range(params: dict, scale: Scale) -> None:
    lo, hi = float(params["u_min"]), float(params["u_max"])
    span = scale.drive_max_v - scale.drive_min_v
    if abs(lo - scale.drive_min_v) > 1e-6 * abs(span) or abs(hi - scale.drive_max_v) > 1e-6 * abs(span):
        raise TableImageError(
            "out_of_range",
            f"the model normalizes the drive over [{lo:g}, {hi:g}] V but the controller's drive range is "
            f"[{scale.drive_min_v:g}, {scale.drive_max_v:g}] V: identify again with "
            f"--u-range {scale.drive_min_v:g} {scale.drive_max_v:g}")


def _open_loop_line(model: Model, scale: Scale) -> tuple[float, float]:
    """u = g r + o [FS]: least squares through the model's slow full-range sweep."""
    v = np.concatenate([np.linspace(-1, 1, 2001), np.linspace(1, -1, 2001)] * 2)
    u = scale.drive_from_fs(v)
    y = get_kind(model.kind).simulate(model.params, np.arange(v.size) * 1e-3, u)
    r = scale.position_to_fs(y)
    A = np.column_stack([r, np.ones_like(r)])
    (g, o), *_ = np.linalg.lstsq(A, v, rcond=None)
    if not g > 0:
        raise TableImageError("out_of_range", "the model's displacement does not grow with the drive")
    return float(g), float(o)


def _eupi_sections(model: Model, scale: Scale, margin: float):
    p = model.params
    _check_drive_range(p, scale)
    ep = eupi_to_params(p)
    s = float(p["y_half"]) / scale.p_half
    shift = (float(p["y_mid"]) - scale.p_mid) / scale.p_half
    scaled = EUPIParams(a0=ep.a0 * s, r_cpi=ep.r_cpi, b=np.asarray(ep.b) * s, r_upi=ep.r_upi, a_upi=ep.a_upi,
                        d=np.asarray(ep.d) * s, p=np.asarray(ep.p) * s, p0=ep.p0 * s + shift, k_ex=0.0)
    try:
        kex = choose_kex(scaled, -1.0, 1.0, margin=margin * s)
    except ValueError as exc:
        raise TableImageError("unstable_inverse", f"no k_ex makes the inverse a contraction: {exc}") from None
    # the firmware bounds |P'| by sum (m + 2) |p_m| (coefset.c), more loosely
    # than the float check: raise k_ex until that bound holds with the margin too
    big_s = float(np.sum(np.asarray(scaled.d) * np.maximum(1.0, np.asarray(scaled.a_upi))[None, :])) if scaled.d.size else 0.0
    pb = float(sum((m + 2) * abs(c) for m, c in enumerate(np.ravel(scaled.p))))
    if not scaled.a0 > pb + margin * s:
        raise TableImageError("unstable_inverse",
                              f"a0 = {scaled.a0:.4g} does not exceed the firmware's bound on the polynomial's "
                              f"slope {pb:.4g}: fit with fewer polynomial terms (--eupi-poly)")
    kex = max(kex, 0.5 * (big_s + pb - scaled.a0 + 2 * margin * s))
    scaled = apply_kex(scaled, kex)
    try:
        q = ginv.quantize_eupi_inv(scaled)
    except ValueError as exc:
        raise TableImageError("out_of_range", str(exc)) from None
    info = {"k_ex": kex, "small_gain_margin": small_gain_margin(scaled, -1, 1),
            "fixed": lambda r_q15: ginv.eupi_inv_run(q, r_q15),
            "float": lambda r_fs: eupi_inverse(r_fs, scaled)}
    return eupi_inverse_sections(q, scaled.a0), info


def _kp_sections(model: Model, scale: Scale):
    p = model.params
    _check_drive_range(p, scale)
    grid = grid_of(p)
    w = np.asarray(p["w"], dtype=np.float64) / scale.p_half
    c1 = float(p.get("linear", 0.0)) / scale.p_half
    c = (float(p["offset"]) - scale.p_mid) / scale.p_half
    big_w = float(np.sum(w)) + c1
    if not big_w > 0:
        raise TableImageError("out_of_range", "the KP model has no positive gain to invert")
    try:
        d = gdcc.quantize(grid, w, gain=1.0 / big_w)
    except ValueError as exc:
        raise TableImageError("out_of_range", str(exc)) from None
    g = 1.0 / big_w

    def fixed(r_q15):
        yd = np.clip(np.floor(np.asarray(r_q15, dtype=np.float64) - c * 32768 + 0.5), -32768, 32767)
        return gdcc.dcc_process_q(yd.astype(np.int64), d)

    def flt(r_fs):
        # the linear term c1 v acts as one more operator with Psi = 0 (psi = v)
        return kpref.dcc_law(np.asarray(r_fs, dtype=np.float64) - c, grid, w, gain=g)

    return kp_dcc_sections(d), {"dcc_gain": g, "y_offset": -c, "fixed": fixed, "float": flt}


@dataclass
class Compiled:
    """A model compiled for a controller: what the table will make it do.

    Attributes
    ----------
    table_kind : str
    sections : list
        Payload sections (controller scalars first).
    inverse_fixed : callable
        Reference q15 -> drive q15, bit-exact with the firmware (golden model).
    inverse_float : callable
        Reference [FS] -> drive [FS], float64.
    line : tuple of float
        The uncompensated straight line (gain, offset) [FS].
    info : dict
        Kind-specific figures (k_ex, small-gain margin, DCC gain...).
    """

    table_kind: str
    sections: list
    inverse_fixed: object
    inverse_float: object
    line: tuple
    info: dict


def compile_model(model: Model, scale: Scale, *, margin: float = 0.02) -> Compiled:
    """Map, quantize and check a model for a controller (see the module docstring).

    Raises
    ------
    TableImageError
        With the firmware's reason name, before anything is flashed.
    """
    if model.kind not in SUPPORTED_KINDS:
        raise TableImageError("bad_kind", f"no firmware table for model kind {model.kind!r} "
                                          f"(tables exist for: {', '.join(SUPPORTED_KINDS)})")
    if float(model.params.get("input_delay_s", 0.0)) != 0.0:
        raise TableImageError("out_of_range", "the model was fitted with an input delay; the firmware "
                                              "compensator has none: identify without --delay-s")
    if model.kind == "eupi":
        sections, info = _eupi_sections(model, scale, margin)
        y_gain, y_off = 1.0, 0.0
    else:
        sections, info = _kp_sections(model, scale)
        y_gain, y_off = 1.0, info["y_offset"]
    g, o = _open_loop_line(model, scale)
    sections = [ctl_section(g, o, y_gain, y_off)] + sections
    fixed, flt = info.pop("fixed"), info.pop("float")
    return Compiled(SUPPORTED_KINDS[model.kind], sections, fixed, flt, (g, o), info)


def table_from_model(model: Model, scale: Scale, *, table_version: int | None = None,
                     margin: float = 0.02, axis: int = 0) -> bytes:
    """Build the table image of an identified model for a controller's scale.

    Parameters
    ----------
    model : Model
        A loaded model file of a kind in :data:`SUPPORTED_KINDS`.
    scale : Scale
        The controller's q15 scale.
    table_version : int, optional
        Version stamped into the header (default: Unix time).
    axis : int
        The controller axis the table is for; with ``scale`` it is stamped
        into the header, and a controller of another stage or axis refuses it.
    margin : float
        Small-gain margin the EUPI inverse must keep [FS per FS, in the model's output units].

    Raises
    ------
    TableImageError
        With the firmware's reason name, before anything is flashed.
    """
    comp = compile_model(model, scale, margin=margin)
    data = model.provenance.get("data", [])
    digest = hashlib.sha256("".join(d.get("sha256", "") for d in data).encode()).digest()
    nrmse = max([float(d.get("nrmse", 0.0)) for d in data] or [0.0])
    now = int(time.time())
    return build_image(comp.table_kind, comp.sections,
                       table_version=int(table_version if table_version is not None else now),
                       fit_nrmse=nrmse, build_time=now, data_sha256=digest, axis=axis,
                       drive_range_v=(scale.drive_min_v, scale.drive_max_v),
                       position_range_um=(scale.position_min_um, scale.position_max_um))
