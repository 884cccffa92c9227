"""Tables for the default SIL stage: the host's calibration pipeline, offline.

``c_header()`` (run at build time by ``tests/firmware/sil.cmake``) does what
the host does with a real stage, against the C stage model
(:func:`piezoctl.sil.stage.simulate_stage`, ``stages/default.json``):

1. excite the stage: quasi-static nested-amplitude sweeps of the full drive
   range (a major loop, first-order reversal curves from both ends, a
   decaying centred triangle) for the hysteresis models, and a small
   random-phase multisine around mid-drive for the feedback design;
2. convert drive and measured position to the controller's normalized q15
   coordinates with the scale of ``piezo_sil_ctl_config()``: drive
   ``amplifier gain * DAC range + offset`` -> [-1, 1), position ``ADC range``
   -> [-1, 1) (so q15 0 is mid-ADC range, not the stage at rest);
3. identify the models with the project's identification code
   (:func:`piezoctl.ident.eupi.fit`, :func:`piezoctl.ident.kp.fit`);
4. quantize with the golden quantizers and build the table images
   (``eupi_inverse`` and ``kp_dcc``);
5. design the feedback (PI + notch at the first mode) on the measured
   frequency response;
6. emit the images, the scale, the uncompensated (straight-line) gain, the
   reference and the feedback coefficients as C declarations.

Coordinates: ``v`` is the drive and ``y`` the position, both in full-scale
units of the controller (q15 / 2^15).

Offsets. q15 0 of the position is mid-ADC range (10 um), not the stage at
rest (-0.83 FS), so every law needs an offset: the EUPI inverse has its
``p0``; the uncompensated drive ``u = a r + b`` and the DCC law's input
``yd = r - c`` (``c`` the KP fit's offset) are the controller's straight-line
scalars (``ctl_section``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

from .. import fixed
from ..fixed import Q15, Q24
from ..ident import eupi as ident_eupi
from ..ident import kp as ident_kp
from ..ident.common import Options
from ..io.recording import Recording
from ..models import eupi as feupi
from ..models import kp as fkp
from ..sil.stage import default_stage_path, simulate_stage
from ..tables.build import ctl_section, eupi_inverse_sections, kp_dcc_sections
from ..tables.image import build_image
from . import dcc as gdcc
from . import eupi_inv as ginv
from .export import CHeader

__all__ = ["FS", "Scale", "stage_scale", "calibration_drive", "calibrate", "fit_eupi", "fit_kp",
           "dcc_law_params", "straight_line", "design_feedback", "Tables", "build_tables",
           "c_header"]

FS = 10000.0              # tick rate [Hz]
STROKE_FRACTION = 0.8     # reference: 80 % of the stroke, centred
FREQS_HZ = (1.0, 10.0, 50.0)
CAL_RATE_V_PER_S = 600.0  # calibration sweep rate
SEED_CAL = 11             # sensor noise of the calibration runs
KP_LEVELS = 20            # DCC grid: L = 20, 210 operators
EUPI_OPTIONS = dict(eupi_n_cpi=12, eupi_n_upi=4, eupi_n_tilts=2, eupi_poly=3, eupi_margin=0.05)


@dataclass(frozen=True)
class Scale:
    """Physical value of q15 -32768 and +32768 (``piezo_scale_t``)."""

    drive_min_v: float
    drive_max_v: float
    position_min_um: float
    position_max_um: float

    def v_of_volts(self, volts):
        mid, half = 0.5 * (self.drive_min_v + self.drive_max_v), 0.5 * (self.drive_max_v - self.drive_min_v)
        return (np.asarray(volts, dtype=np.float64) - mid) / half

    def y_of_um(self, um):
        mid = 0.5 * (self.position_min_um + self.position_max_um)
        half = 0.5 * (self.position_max_um - self.position_min_um)
        return (np.asarray(um, dtype=np.float64) - mid) / half

    def um_of_y(self, y):
        mid = 0.5 * (self.position_min_um + self.position_max_um)
        half = 0.5 * (self.position_max_um - self.position_min_um)
        return np.asarray(y, dtype=np.float64) * half + mid


def stage_scale(path: Path | None = None) -> Scale:
    """The scale ``piezo_sil_ctl_config()`` derives for axis 0 of a stage file.

    Read from the file's keys (the C test checks the result against
    ``piezo_sil_ctl_config()``, so a disagreement fails the build's test).
    """
    p = json.loads(Path(path or default_stage_path()).read_text())
    a = p["axes"][0]
    g, off = float(a["amplifier"]["gain"]), float(a["amplifier"]["offset_v"])
    v0, v1 = (float(x) for x in a["dac"]["range_v"])
    y0, y1 = (float(x) for x in a["adc"]["range_um"])
    return Scale(g * v0 + off, g * v1 + off, y0, y1)


# ------------------------------------------------------------- excitation

def _ramp_through(points, rate_v_per_s: float) -> np.ndarray:
    """Piecewise-linear drive [V] through ``points`` at a constant rate."""
    out = [np.array([points[0]], dtype=np.float64)]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(round(abs(b - a) / rate_v_per_s * FS)))
        out.append(a + (b - a) * np.arange(1, n + 1) / n)
    return np.concatenate(out)


def calibration_drive(sc: Scale, rate_v_per_s: float = None) -> np.ndarray:
    """Quasi-static nested-amplitude sweeps [V]: rest, a ramp to full drive,
    then triangles centred on mid-drive with amplitudes 100 %, 95 %, ... 20 %
    of half the range, two cycles each, and back to rest.

    Centred nested loops are what the stage does under the references it
    will follow (triangles and sines around a working point); on the default
    stage they fit the operating loop 4x better than first-order reversal
    curves from the ends (whose Bouc-Wen minor loops a Prandtl-Ishlinskii
    model cannot follow everywhere at once). 600 V/s (a full loop in 0.5 s)
    is slow for the stage's rate dependence (alpha grows by 1.7 %).
    """
    rate_v_per_s = CAL_RATE_V_PER_S if rate_v_per_s is None else rate_v_per_s
    lo, hi = 0.0, sc.drive_max_v          # the amplifier's output: 0 V (rest) .. full drive
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    pts = [lo, hi]
    for k in range(20, 3, -1):
        pts += [mid - half * k / 20.0, mid + half * k / 20.0] * 2
    pts += [lo]
    u = _ramp_through(pts, rate_v_per_s)
    return np.concatenate([np.full(int(0.2 * FS), lo), u])


def calibrate(sc: Scale, path: Path | None = None, seed: int = SEED_CAL):
    """Run the calibration drive on the stage: (v, y) in controller FS units."""
    u = calibration_drive(sc)
    t = np.arange(u.size) / FS
    y_um = simulate_stage(path or default_stage_path(), t, u, seed=seed)
    return t, u, y_um


# ------------------------------------------------------------- models

def _recording(sc: Scale, t, u_v, y_um) -> Recording:
    # drive in volts (normalized by u_range = the scale), position in controller FS units
    return Recording(t=t, u=np.asarray(u_v, dtype=np.float64), y=sc.y_of_um(y_um))


def fit_eupi(sc: Scale, rec: Recording) -> tuple[feupi.EUPIParams, dict]:
    """EUPI model in controller coordinates (v -> y, both FS), with its k_ex."""
    opts = Options(u_range=(sc.drive_min_v, sc.drive_max_v), offset="shared", max_fit_rows=200_000,
                   **EUPI_OPTIONS)
    p = ident_eupi.fit([rec], opts)
    # the fit's output is z = (y - y_mid) / y_half: scale to y (linear in every weight)
    m, h = float(p["y_mid"]), float(p["y_half"])
    base = feupi.EUPIParams(a0=p["a0"] * h, r_cpi=p["r_cpi"], b=np.asarray(p["b"]) * h,
                            r_upi=p["r_upi"], a_upi=p["a_upi"], d=np.asarray(p["d"]) * h,
                            p=np.asarray(p["p"]) * h, p0=p["p0"] * h + m, k_ex=0.0)
    kex = feupi.choose_kex(base, -1.0, 1.0, margin=float(EUPI_OPTIONS["eupi_margin"]) * h)
    return feupi.apply_kex(base, kex), p


def fit_kp(sc: Scale, rec: Recording) -> dict:
    """KP model in controller coordinates: y = sum w psi(v) + c1 v + c."""
    opts = Options(u_range=(sc.drive_min_v, sc.drive_max_v), offset="shared", max_fit_rows=200_000,
                   kp_levels=KP_LEVELS, kp_ridge=None, kp_linear="on", kp_signed=False)
    return ident_kp.fit([rec], opts)


def dcc_law_params(p: dict) -> tuple[fkp.KPGrid, np.ndarray, float, float]:
    """The DCC law of a KP fit ``y = sum w psi(v) + c1 v + c``: (grid, w, g, c).

    With ``psi_j = v - Psi_j``, ``y = (W + c1) v - sum w Psi + c``, so
    ``v = g (y - c + sum w Psi)``, ``g = 1 / (W + c1)``: the kernel's law with
    the gain ``g`` and the input ``yd = r - c``.
    """
    w = np.asarray(p["w"], dtype=np.float64)
    g = 1.0 / (float(np.sum(w)) + float(p["linear"]))
    return ident_kp.grid_of(p), w, g, float(p["offset"])


def straight_line(v, y) -> tuple[float, float]:
    """Least-squares ``v = a y + b`` (drive per displacement): (a, b)."""
    A = np.column_stack([y, np.ones_like(y)])
    a, b = np.linalg.lstsq(A, v, rcond=None)[0]
    return float(a), float(b)


# ------------------------------------------------------------- feedback

@dataclass(frozen=True)
class Feedback:
    kp: float
    ki: float          # per tick
    notch_hz: float
    notch_q: float
    notch_b: np.ndarray
    notch_a: np.ndarray
    crossover_hz: float
    phase_margin_deg: float
    ms: float
    loop_gain_50hz: float
    preview_ticks: int = 0       # feedforward look-ahead: the stage's delay plus the shaper's
    shaper_ticks: int = 0        # ZVD input shaper at the first mode (calibrate.feedback)
    shaper_q15: tuple = (32768, 0, 0)


def measure_frf(sc: Scale, path: Path | None = None, seed: int = 5, n: int = 1 << 16,
                amp_v: float = 6.0):
    """Frequency response y/v (controller FS units) around mid-drive.

    A random-phase multisine (every FFT bin up to 4 kHz, peak ``amp_v``)
    repeated three times; the last two periods are averaged.
    """
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1.0 / FS)
    spec = np.zeros(f.size, dtype=complex)
    band = (f > 0) & (f < 4000.0)
    spec[band] = np.exp(2j * np.pi * rng.random(np.count_nonzero(band)))
    x = np.fft.irfft(spec, n)
    x *= amp_v / np.max(np.abs(x))
    mid = 0.5 * (sc.drive_min_v + sc.drive_max_v)
    u = np.concatenate([np.full(int(0.5 * FS), mid), mid + np.tile(x, 3)])
    t = np.arange(u.size) / FS
    y = simulate_stage(path or default_stage_path(), t, u, seed=seed)
    U = np.fft.rfft(sc.v_of_volts(u[-2 * n:]).reshape(2, n), axis=1).mean(axis=0)
    Y = np.fft.rfft(sc.y_of_um(y[-2 * n:]).reshape(2, n), axis=1).mean(axis=0)
    return f[band], Y[band] / U[band]


MAX_MS = 1.6              # sensitivity peak: modulus margin 0.625 (GM >= 8.5 dB, PM >= 36 deg)
MIN_PM_DEG = 45.0


def loop_margins(f, L):
    """(crossover [Hz], phase margin [deg], Ms) of a loop response, or None
    when the unwrapped phase reaches -180 deg below the last crossover (for a
    stable plant and an integrating loop that starts at -90 deg this, with
    |L| < 1 above the crossover, rules out an encirclement of -1)."""
    m = np.abs(L)
    ph = np.unwrap(np.angle(L))
    above = np.nonzero(m >= 1.0)[0]
    if above.size == 0:
        return None
    ic = int(above[-1])
    if np.any(ph[:ic + 1] <= -np.pi):
        return None
    return float(f[ic]), 180.0 + float(np.degrees(ph[ic])), float(np.max(1.0 / np.abs(1.0 + L)))


def design_feedback(sc: Scale, path: Path | None = None) -> Feedback:
    """PI + notch on the measured frequency response.

    The notch (``scipy.signal.iirnotch``) sits at the largest peak of |P|
    (the first mode). The tick adds one sample of delay (the controller reads
    the ADC value of the previous tick): L = C N P z^-1. Over a grid of notch
    widths Q, integral gains ki (per tick) and proportional gains kp, the
    design keeps those with Ms <= 1.6 and phase margin >= 45 deg, and takes
    the one with the largest |L| at 50 Hz (the highest test frequency).
    """
    f, P = measure_frf(sc, path)
    keep = f > 5.0
    f, P = f[keep][::4], P[keep][::4]       # 0.6 Hz spacing: the mode is 23 Hz wide
    z = np.exp(2j * np.pi * f / FS)
    f0 = float(f[np.argmax(np.abs(P))])
    i50 = int(np.argmin(np.abs(f - 50.0)))
    best = None
    for q in (0.5, 1.0, 2.0, 4.0):
        b, a = signal.iirnotch(f0, q, fs=FS)
        N = (b[0] + b[1] / z + b[2] / z ** 2) / (a[0] + a[1] / z + a[2] / z ** 2)
        for ki in np.geomspace(0.005, 0.5, 81):
            for kp in np.arange(0.0, 1.0001, 0.05):
                L = (ki / (1.0 - 1.0 / z) + kp) * N * P / z
                m = loop_margins(f, L)
                if m is None or m[2] > MAX_MS or m[1] < MIN_PM_DEG:
                    continue
                if best is None or abs(L[i50]) > best[0]:
                    best = (abs(L[i50]), Feedback(kp=float(kp), ki=float(ki), notch_hz=f0, notch_q=q,
                                                  notch_b=b, notch_a=a, crossover_hz=m[0],
                                                  phase_margin_deg=m[1], ms=m[2],
                                                  loop_gain_50hz=float(abs(L[i50]))))
    if best is None:
        raise ValueError("no PI + notch meets the margins on the measured response")
    # the feedforward path: a ZVD shaper at the mode, and a preview of the
    # stage's group delay (below a third of the mode) plus the shaper's delay
    import dataclasses
    import types
    from ..calibrate.feedback import damping, group_delay_ticks, zvd_shaper
    frf = types.SimpleNamespace(f_hz=f, mag=np.abs(P), phase_deg=np.degrees(np.unwrap(np.angle(P))))
    m, taps = zvd_shaper(f0, damping(frf, f0), FS)
    delay = group_delay_ticks(frf, FS, f0 / 3.0)
    return dataclasses.replace(best[1], preview_ticks=int(min(32, delay + m)), shaper_ticks=m,
                               shaper_q15=tuple(taps))


# ------------------------------------------------------------- tables

@dataclass(frozen=True)
class Tables:
    """Everything the closed-loop test needs (controller FS units)."""

    scale: Scale
    eupi_img: bytes
    dcc_img: bytes
    ol_gain: float         # a of the straight line u = a y + b
    ol_offset: float       # b
    ref_offset: float      # centre of the reference [FS]
    ref_amplitude: float   # half its peak-to-peak [FS]
    fb: Feedback
    info: dict


def reference_triangle(off: float, amp: float, f_hz: float, periods: float = 1.0) -> np.ndarray:
    """The wave generator's triangle (float): starts at ``off`` rising, peak at 1/4 period."""
    n = int(round(periods * FS / f_hz))
    ph = (np.arange(n) * f_hz / FS) % 1.0
    shape = np.where(ph < 0.25, 4 * ph, np.where(ph < 0.75, 2 - 4 * ph, 4 * ph - 4))
    return off + amp * shape


def build_tables(path: Path | None = None) -> Tables:
    """Calibrate, identify, quantize and build the tables (see the module docstring)."""
    sc = stage_scale(path)
    t, u_v, y_um = calibrate(sc, path)
    v, y = sc.v_of_volts(u_v), sc.y_of_um(y_um)
    info = {}
    # stroke: the span of the steady full-drive loop (the two 0 V - full drive
    # cycles after the first ramp); the stage does not return to its rest
    # position (0 um) under cycling. The reference: 80 % of it, centred.
    k0 = int(np.argmax(u_v))
    loop = slice(k0, k0 + int(round(4 * sc.drive_max_v / CAL_RATE_V_PER_S * FS)))
    y_lo, y_hi = float(np.min(y[loop])), float(np.max(y[loop]))
    ref_off = 0.5 * (y_lo + y_hi)
    ref_amp = 0.5 * STROKE_FRACTION * (y_hi - y_lo)
    um_per_fs = 0.5 * (sc.position_max_um - sc.position_min_um)
    info["stroke_um"] = (y_hi - y_lo) * um_per_fs
    # EUPI: from the first full-drive peak on, where every play operator's
    # state is known (u - r) whatever came before; the fit starts them at 0
    ep, _ = fit_eupi(sc, _recording(sc, t[k0:] - t[k0], u_v[k0:], y_um[k0:]))
    info["eupi_rms_um"] = float(np.sqrt(np.mean((feupi.eupi_model(v[k0:], ep) - y[k0:]) ** 2))) * um_per_fs
    info["eupi_k_ex"] = ep.k_ex
    info["eupi_margin"] = feupi.small_gain_margin(ep, -1.0, 1.0)
    q = ginv.quantize_eupi_inv(ep)
    # KP: from rest, which is the KP reset state (all operators 0, input at the bottom)
    rec = _recording(sc, t, u_v, y_um)
    kp = fit_kp(sc, rec)
    info["kp_rms_um"] = float(np.sqrt(np.mean((ident_kp.simulate(kp, t, u_v) - y) ** 2))) * um_per_fs
    grid, w, g, c = dcc_law_params(kp)
    d = gdcc.quantize(grid, w, gain=g)
    a, b = straight_line(v, y)
    info["line_rms_um"] = float(np.sqrt(np.mean((a * y + b - v) ** 2))) * um_per_fs / a
    # both tables carry the straight line for OPEN_LOOP (the uncompensated baseline)
    stage = dict(axis=0, drive_range_v=(sc.drive_min_v, sc.drive_max_v),
                 position_range_um=(sc.position_min_um, sc.position_max_um))
    eupi_img = build_image("eupi_inverse", [ctl_section(a, b)] + eupi_inverse_sections(q, ep.a0),
                           table_version=1, **stage)
    dcc_img = build_image("kp_dcc", [ctl_section(a, b, 1.0, -c)] + kp_dcc_sections(d), table_version=2, **stage)
    fb = design_feedback(sc, path)
    return Tables(sc, eupi_img, dcc_img, a, b, ref_off, ref_amp, fb, info)


def _q24(x: float) -> int:
    return fixed.to_q(float(x), Q24)


def _q15(x: float) -> int:
    return fixed.to_q(float(x), Q15)


def c_header() -> str:
    """Header ``sil_tables_vectors.h`` for tests/firmware/test_sil_closed_loop.c."""
    tb = build_tables()
    sc, fb, info = tb.scale, tb.fb, tb.info
    h = CHeader("sil_tables")
    h.comment("Tables for the default SIL stage from the host's calibration pipeline "
              "(piezoctl.golden.sil_tables): nested sweeps of the C stage model, "
              "ident.eupi / ident.kp fits, golden quantizers, PI + notch on the measured response.")
    h.comment(f"stroke {info['stroke_um']:.3f} um; fit RMS over the calibration: EUPI "
              f"{info['eupi_rms_um']:.4f} um, KP {info['kp_rms_um']:.4f} um, straight line "
              f"{info['line_rms_um']:.4f} um; EUPI k_ex {info['eupi_k_ex']:.4f}, small-gain margin "
              f"{info['eupi_margin']:.4f}")
    for name, val in (("DRIVE_MIN_V", sc.drive_min_v), ("DRIVE_MAX_V", sc.drive_max_v),
                      ("POSITION_MIN_UM", sc.position_min_um), ("POSITION_MAX_UM", sc.position_max_um)):
        h.parts.append(f"#define SIL_SCALE_{name} ({val!r})")
    h.array("sil_eupi_img", "uint8_t", np.frombuffer(tb.eupi_img, np.uint8))
    h.define("SIL_EUPI_IMG_LEN", len(tb.eupi_img))
    h.array("sil_dcc_img", "uint8_t", np.frombuffer(tb.dcc_img, np.uint8))
    h.define("SIL_DCC_IMG_LEN", len(tb.dcc_img))
    h.comment(f"uncompensated (OPEN_LOOP): u = a r + b, a = {tb.ol_gain:.5f}, b = {tb.ol_offset:.5f} FS")
    h.define("SIL_OL_GAIN_Q24", _q24(tb.ol_gain))
    h.comment(f"reference: triangle, 80 % of the stroke, centre {sc.um_of_y(tb.ref_offset):.4f} um, "
              f"amplitude {tb.ref_amplitude * 0.5 * (sc.position_max_um - sc.position_min_um):.4f} um")
    h.define("SIL_REF_OFFSET_Q15", _q15(tb.ref_offset))
    h.define("SIL_REF_AMPLITUDE_Q15", _q15(tb.ref_amplitude))
    h.comment(f"feedback: PI kp {fb.kp:.3f}, ki {fb.ki:.5f} per tick ({fb.ki * FS:.1f} /s); notch "
              f"{fb.notch_hz:.1f} Hz, Q {fb.notch_q:g}; crossover {fb.crossover_hz:.1f} Hz, phase "
              f"margin {fb.phase_margin_deg:.1f} deg, Ms {fb.ms:.3f}, |L(50 Hz)| {fb.loop_gain_50hz:.2f}")
    h.comment(f"feedforward: preview {fb.preview_ticks} ticks, ZVD shaper every {fb.shaper_ticks} ticks")
    h.define("SIL_PREVIEW_TICKS", fb.preview_ticks)
    h.define("SIL_SHAPER_TICKS", fb.shaper_ticks)
    for i, v in enumerate(fb.shaper_q15):
        h.define(f"SIL_SHAPER_Q15_{i}", v)
    h.define("SIL_FB_KP_Q24", _q24(fb.kp))
    h.define("SIL_FB_KI_Q24", _q24(fb.ki))
    h.define("SIL_FB_KD_Q24", 0)
    nb, na = fb.notch_b / fb.notch_a[0], fb.notch_a / fb.notch_a[0]
    for name, val in (("B0", nb[0]), ("B1", nb[1]), ("B2", nb[2]), ("A1", na[1]), ("A2", na[2])):
        h.define(f"SIL_NOTCH_{name}_Q24", _q24(val))
    h.parts.append(f"#define SIL_NOTCH_HZ ({fb.notch_hz!r})")
    return str(h)
