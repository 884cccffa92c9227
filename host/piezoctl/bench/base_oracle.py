"""Where the base's held-out error on a null comes from (docs/diagnose-rounds/round-19.md, "Round 19: the base on nulls").

For each null case of a foreign seed (drawn and written as ``tools/bench-base --nulls`` does, scale 1), the base
is fitted on the case's calibration as ``diagnose`` fits it and each reveal recording's error (settled samples
inside the calibrated drive range, RMS [nm] and the same without its mean) is set beside what planes of the
base's family reach on the *noise-free static* output (the hysteresis law through the amplifier and the sensor,
the stage's modes replaced by their unit static gain; drawn by the generator ``write_case`` uses, noise 0):

- ``total``: the base (the figure of ``tools/bench-base --nulls``);
- ``static``: the base's plane alone (its dynamics set to 1) against the static output;
- ``modes``: what the stage's modes do to the recording (noise-free output minus static output);
- ``o_cal``: a plane of the size, ridge and column the base chose, fitted on the noise-free static calibration;
- ``o_calbig``: the largest plane of the family (``OR_PLAYS`` plays, ``OR_KNOTS`` knots, ridge ``OR_RIDGE``, the
  base's column if any) fitted on the same noise-free static calibration, whatever the calibration's reversal
  levels allow;
- ``o_rev``: the largest plane fitted on the recording's own static output (what the family can represent of
  that history at all);
- ``new_levels``: the recording's reversal levels (``base.reversal_levels``'s rule) the calibration never
  reversed at.

Reading: ``total - static`` small: not the dynamics; ``total`` close to ``o_cal``: not the noise (the chosen size
is the limit); ``o_calbig`` far below ``o_cal``: the size choice; ``o_rev`` far below ``o_calbig``: what the
calibration did not show; ``o_rev`` itself large: the family's resolution or the law is not of Preisach type.

    .venv/bin/python -m piezoctl.bench.base_oracle 121 60 5,9,14        # seed, case count (plan), case indices
"""

from __future__ import annotations

import copy
import sys
import tempfile
import time
import zlib

import numpy as np

from ..foreign.stage import FS_HZ, U_HALF_V, U_MID_V
from ..ident import base as B
from ..ident import refined
from ..models.hysteresis import play_states

__all__ = ["static_outputs", "oracle_case", "main"]

SETTLE_S = 0.5
OR_PLAYS, OR_KNOTS, OR_RIDGE = 16, 24, 1e-6
ORACLE_ROWS = 40_000


def static_outputs(case) -> tuple:
    """(calibration, reveal) lists of the null stage's noise-free *static* sensor output [um]: the law through the
    amplifier (gain, offset, latency) and the sensor (gain, offset, curve, quantization), no modes."""
    st = case.stage
    if any(getattr(st, k) is not None for k in ("creep", "drift", "coupling", "rate", "asym")):
        raise ValueError(f"{case.case_id}: not a null stage")
    sensor = copy.deepcopy(st.sensor)
    sensor.noise_um = 0.0
    rng = np.random.default_rng([0, zlib.crc32(case.case_id.encode())])
    out = []
    for group in (case.calibration, case.reveal):
        g = []
        for r in group:
            n = r.u.size
            reps = int(np.ceil(r.warmup_s * FS_HZ / n)) + 1 if r.warmup_s > 0 else 1
            ua = st.amplifier(np.tile(r.u, reps))
            x = 0.5 * st.stroke_um * (st.law((ua - U_MID_V) / U_HALF_V) + 1)
            g.append(sensor.read(x, r.session, 0.5 * st.stroke_um, 0.5 * st.stroke_um, rng)[-n:])
        out.append(g)
    return out[0], out[1]


def _plane(v_fit, y_fit, m_fit, v_all, R, K, bw, ridge, v_rest, sign):
    """A plane (R plays, K knots, Bouc-Wen column ``bw``) fitted by the base's solver on the rows ``m_fit``;
    every play's span taken over ``v_all``. Returns the predictor v -> output [um]."""
    r_all = np.array(sorted({j / R2 for R2 in B.PLANE_PLAYS + (R,) for j in range(R2)}))
    ex = [play_states(np.ascontiguousarray(v), r_all, v_rest) for v in v_all]
    spans = [(float(min(P[:, i].min() for P in ex)), float(max(P[:, i].max() for P in ex))) for i in range(r_all.size)]
    lay = B.PlaneLayout(R, K, spans, r_all, bw=bw)
    blocks = []
    for v, y, m in zip(v_fit, y_fit, m_fit):
        rows = B._strided(m, ORACLE_ROWS // len(v_fit))
        P = play_states(np.ascontiguousarray(v), r_all, v_rest)
        blocks.append((np.column_stack([B.plane_columns(P, lay, rows, v, v_rest), np.ones(rows.size)]), y[rows]))
    A, b, _, _ = B._gram(blocks)
    th = B._plane_solve(A, b, ridge, B.smoothness_penalty(lay, 1), lay, sign)
    return lambda v: (B.plane_columns(play_states(np.ascontiguousarray(v), r_all, v_rest), lay, None, v, v_rest)
                      @ th[:lay.n_cols] + th[-1])


def _levels(vs, k0s, deadband=0.02, resolution=1.0 / 32) -> set:
    """The set of reversal levels ``base.reversal_levels`` counts."""
    from ..dsp import turning_points
    levels = set()
    for v, k0 in zip(vs, k0s):
        p = play_states(np.asarray(v, float)[k0:], [deadband], float(v[k0]))[:, 0]
        d = np.sign(np.diff(p))
        for i in turning_points(p):
            levels.add((int(d[i] > 0), int(np.round(p[i] / (2.0 * resolution)))))
    return levels


def _rms(e, m) -> list:
    return [1000 * float(np.sqrt(np.mean(e[m] ** 2))), 1000 * float(np.std(e[m]))] if m.any() else [np.nan] * 2


def oracle_case(seed: int, index: int, truth=()) -> dict:
    """The split of one null case (module doc); figures [nm] as (RMS, RMS without the mean) per reveal recording."""
    from ..foreign.cases import draw_case, write_case
    from ..io.recording import load_recording
    from .base_laws import _noise_free
    case = draw_case(seed, index, truth)
    with tempfile.TemporaryDirectory(prefix="base-oracle-") as d:
        files = write_case(case, d)
        cal = [load_recording(p) for p in files["calibration"]]
        rev = [load_recording(p) for p in files["recordings"]]
    base = B.fit_base(cal, settle_s=SETTLE_S, holdout=True)
    info = base.pop("base_info")["plane"]
    base.pop("_holdout", None)
    y0s = _noise_free(case)
    cs, rs = static_outputs(case)
    k0c = [int(round(SETTLE_S * r.sample_rate_hz)) for r in cal]
    k0r = [int(round(SETTLE_S * r.sample_rate_hz)) for r in rev]
    lo = min(float(np.min(r.u[k:])) for r, k in zip(cal, k0c))
    hi = max(float(np.max(r.u[k:])) for r, k in zip(cal, k0c))
    mid, half, v_rest = base["u_mid"], base["u_half"], base["hysteresis"]["v_rest"]
    vc = [(r.u - mid) / half for r in cal]
    vr = [(r.u - mid) / half for r in rev]
    mc = [np.arange(v.size) >= k for v, k in zip(vc, k0c)]
    mr = [(np.arange(v.size) >= k) & (r.u >= lo) & (r.u <= hi) for v, k, r in zip(vr, k0r, rev)]
    sign = B._output_sign(vc, cs, k0c)
    bw = tuple(info["bouc_wen"]) if info["bouc_wen"] else None
    o_cal = _plane(vc, cs, mc, vc + vr, info["plays"], info["knots"], bw, info["ridge"], v_rest, sign)
    o_big = _plane(vc, cs, mc, vc + vr, OR_PLAYS, OR_KNOTS, bw, OR_RIDGE, v_rest, sign)
    static = copy.deepcopy(base)
    static["dynamics"] = {"b": [1.0], "a": [1.0]}
    cal_levels = _levels(vc, k0c)
    rows = []
    for r, name, y0, ys, v, k, m in zip(rev, files["recordings"], y0s, rs, vr, k0r, mr):
        o_rev = _plane([v], [ys], [m], [v], OR_PLAYS, OR_KNOTS, bw, OR_RIDGE, v_rest, sign)
        lv = _levels([v], [k])
        rows.append({"name": name.split("/")[-1], "total": _rms(refined.simulate(base, r.t, r.u, r.u2) - y0, m),
                     "static": _rms(refined.simulate(static, r.t, r.u, r.u2) - ys, m), "modes": _rms(y0 - ys, m),
                     "o_cal": _rms(o_cal(v) - ys, m), "o_calbig": _rms(o_big(v) - ys, m),
                     "o_rev": _rms(o_rev(v) - ys, m), "levels": len(lv), "new_levels": len(lv - cal_levels)})
    return {"id": case.case_id, "law": case.stage.law.name, "noise_nm": 1000 * case.stage.sensor.noise_um,
            "plane": f"R{info['plays']} K{info['knots']} ridge {info['ridge']:g}" + (" + Bouc-Wen" if bw else ""),
            "cal_levels": len(cal_levels), "rows": rows}


def main(argv=None) -> int:
    from ..foreign.cases import case_plan
    argv = sys.argv[1:] if argv is None else argv
    seed, n = int(argv[0]), int(argv[1])
    want = None if len(argv) < 3 else {int(x) for x in argv[2].split(",")}
    print(f"foreign seed {seed} nulls: [x noise] RMS (without its mean) per reveal recording; * fast", flush=True)
    for i, truth in enumerate(case_plan(n)):
        if truth or (want is not None and i not in want):
            continue
        t0 = time.time()
        c = oracle_case(seed, i, truth)
        print(f"{c['id']} {c['law']} noise {c['noise_nm']:.1f} nm, {c['plane']}, {c['cal_levels']} calibration "
              f"reversal levels ({time.time() - t0:.0f} s)", flush=True)
        for r in c["rows"]:
            fast = any(k in r["name"] for k in ("sine", "chirp", "step"))
            f = {k: r[k][0] / c["noise_nm"] for k in ("total", "static", "modes", "o_cal", "o_calbig", "o_rev")}
            print(f"   {'*' if fast else ' '}{r['name']:36s} total {f['total']:6.1f} ({r['total'][1] / c['noise_nm']:.1f})"
                  f" static {f['static']:6.1f} modes {f['modes']:5.1f} o_cal {f['o_cal']:6.1f} o_calbig "
                  f"{f['o_calbig']:6.1f} o_rev {f['o_rev']:6.1f} new levels {r['new_levels']}/{r['levels']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
