"""Cross-coupling table for the two-axis SIL stage: the host's pipeline, offline.

``c_header()`` (run at build time for ``tests/firmware/test_xcouple_sil.c``)
identifies the coupling from axis 2 into axis 1 of
``firmware/targets/sil/stages/two_axis.json`` with the C stage model
(:func:`piezoctl.sil.stage.simulate_stage`), as calibrate does on a device:

1. axis 1 held at 5 drive levels (its positions); at each, axis 2 driven with
   75 V for 0.3 s, a chirp 1 -> 60 Hz (2 s) then 0.5 -> 3 Hz (1 s), 75 +- 60 V,
   after 0.5 s of settling; the same run
   with axis 2 held at 75 V (same noise seed) is subtracted: y = the coupled
   displacement of axis 1 [um], x = axis 1's position [um];
2. the samples are aligned as the controller sees them: its input at tick k is
   axis 2's drive of tick k - 1 (``sil_loop.c``) and a drive change it makes at
   tick k first shows in the ADC sample of tick k + 2 (transport delay), so
   the pair (u2 of step n, y after step n + 2) is fitted;
3. the map is identified with :func:`piezoctl.ident.hammerstein.fit_arrays` at
   the kernel's settings (:data:`piezoctl.tables.coupling.KERNEL_SETTINGS`);
4. axis 1's static gain [um per FS of drive] is measured with a small step at
   mid drive, and the table is built with the output in axis-1 drive units
   (:func:`piezoctl.tables.coupling.coupling_table`, x = axis 1's own position).

The header carries the image, the scale and the feedback coefficients (PI with
crossover at an eighth of the 140 Hz mode, notch at the mode) for the test.
"""

from __future__ import annotations

import json

import numpy as np

from .. import fixed
from ..calibrate.feedback import notch
from ..fixed import Q24
from ..ident import hammerstein as ham
from ..sil.stage import default_stage_path, simulate_stage
from ..tables.coupling import KERNEL_SETTINGS, coupling_table
from ..tables.from_model import Scale
from .export import CHeader

__all__ = ["STAGE", "FS", "stage_scale", "coupling_records", "static_gain", "build", "c_header"]

STAGE = default_stage_path("two_axis")
FS = 10000.0
LEVELS_V = (20.0, 50.0, 75.0, 100.0, 130.0)
LEAD = 2          # ticks from the controller's input to the first sample its output affects
SETTLE_S = 0.5
SEED = 21


def stage_scale(path=STAGE, axis: int = 0) -> Scale:
    """The scale ``piezo_sil_ctl_config()`` derives for an axis of a stage file."""
    a = json.loads(open(path).read())["axes"][axis]
    g, off = float(a["amplifier"]["gain"]), float(a["amplifier"]["offset_v"])
    v0, v1 = (float(x) for x in a["dac"]["range_v"])
    y0, y1 = (float(x) for x in a["adc"]["range_um"])
    return Scale(g * v0 + off, g * v1 + off, y0, y1)


def _run(level_v: float, u2_tail: np.ndarray, seed: int, path=STAGE):
    ns = int(SETTLE_S * FS)
    ramp = ns // 2
    n = ns + u2_tail.size
    u1 = np.full(n, level_v)
    u1[:ramp] = np.linspace(0.0, level_v, ramp)
    u2 = np.full(n, 75.0)
    u2[:ramp] = np.linspace(0.0, 75.0, ramp)
    base = u2.copy()
    u2[ns:] = u2_tail
    t = np.arange(n) / FS
    y1, _ = simulate_stage(path, t, u1, u2, seed=seed)
    b1, _ = simulate_stage(path, t, u1, base, seed=seed)
    return u2[ns:], (y1 - b1)[ns:], b1[ns:]


def chirp(duration_s: float, f0: float, f1: float, amp: float = 60.0) -> np.ndarray:
    """75 + amp sin(linear chirp f0 -> f1) [V]."""
    t = np.arange(int(duration_s * FS)) / FS
    return 75.0 + amp * np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / duration_s * t ** 2))


def chirp_drive() -> np.ndarray:
    """The identification drive of axis 2: 75 V held 0.3 s (the model's DC: no
    coupling at the rest drive), 1 -> 60 Hz in 2 s, then 0.5 -> 3 Hz in 1 s."""
    return np.concatenate([np.full(int(0.3 * FS), 75.0), chirp(2.0, 1.0, 60.0), chirp(1.0, 0.5, 3.0)])


def coupling_records(path=STAGE):
    """Aligned training data: lists of u2 [V], x [um], y [um] per axis-1 level."""
    us, xs, ys = [], [], []
    for k, lv in enumerate(LEVELS_V):
        u2, y, b = _run(lv, chirp_drive(), SEED + k, path)
        us.append(u2[:u2.size - LEAD])
        ys.append(y[LEAD:])
        xs.append(np.full(u2.size - LEAD, float(np.mean(b))))
    return us, xs, ys


def static_gain(path=STAGE, level_v: float = 75.0, step_v: float = 3.0) -> float:
    """Axis 1's small-signal static gain [um/V]: a step of ``step_v`` at ``level_v``, 50 ms later."""
    ns = int(SETTLE_S * FS)
    n = ns + int(0.05 * FS)
    t = np.arange(n) / FS
    u = np.full(n, level_v)
    u[: ns // 2] = np.linspace(0.0, level_v, ns // 2)
    u_step = u.copy()
    u_step[ns:] += step_v
    y0, _ = simulate_stage(path, t, u, np.full(n, 75.0), seed=SEED)
    y1, _ = simulate_stage(path, t, u_step, np.full(n, 75.0), seed=SEED)
    return float(np.mean((y1 - y0)[-50:]) / step_v)


def build(path=STAGE):
    """(CouplingTable, Scale, gain [um/V], hammerstein params, axis 1's position at 75 V [um])."""
    sc = stage_scale(path)
    us, xs, ys = coupling_records(path)
    params = ham.fit_arrays(us, xs, ys, **KERNEL_SETTINGS)
    hold_um = float(xs[LEVELS_V.index(75.0)][0])
    g_um_per_v = static_gain(path)
    d_half = 0.5 * (sc.drive_max_v - sc.drive_min_v)
    drive_per_um = 1.0 / (g_um_per_v * d_half)   # FS of drive per um
    tab = coupling_table(params, sc, sc, drive_per_um, x_source=0, axis=0, stage=sc)
    return tab, sc, g_um_per_v, params, hold_um


def c_header() -> str:
    tab, sc, g, params, hold_um = build()
    h = CHeader("xcouple_sil")
    h.comment("cross-coupling table for axis 1 of stages/two_axis.json (piezoctl.golden.xcouple_sil)")
    h.array("xc_sil_table", "uint8_t", np.frombuffer(tab.image, dtype=np.uint8))
    h.define("XC_SIL_TABLE_LEN", len(tab.image))
    d_half = 0.5 * (sc.drive_max_v - sc.drive_min_v)
    p_half = 0.5 * (sc.position_max_um - sc.position_min_um)
    line = g * d_half / p_half      # position FS per drive FS
    fc = 140.0 / 8.0
    ki = 2 * np.pi * fc / FS / line
    b0, b1, b2, a1, a2 = notch(140.0, FS)
    for name, v in (("KP", 0.2 / line), ("KI", ki), ("N_B0", b0), ("N_B1", b1), ("N_B2", b2), ("N_A1", a1),
                    ("N_A2", a2)):
        h.define(f"XC_SIL_{name}_Q24", fixed.to_q(v, Q24))
    h.define("XC_SIL_HOLD_Q15", int(np.floor(sc.position_to_fs(hold_um) * 32768 + 0.5)))
    h.comment(f"static gain {g:.6f} um/V; scale drive {sc.drive_min_v:g}..{sc.drive_max_v:g} V, "
              f"position {sc.position_min_um:g}..{sc.position_max_um:g} um")
    return str(h)
