"""The diagnosis pipeline: load, base, locate, select, refine, report (docs/diagnose.md).

``diagnose()`` runs the stages in order; each stage is one function here:

1. :func:`load` the recordings (one sample rate, unique names);
2. :func:`fit_base_model` on the calibration (``piezoctl.ident.base``), written as ``base_model.json``;
3. :func:`locate` the mismatch: the context the terms read, the residual analysis, the
   samples outside the calibrated drive range;
4. select terms (``select.py``: cross-validated, nested, exact);
5. :func:`refine`: the refined model and its exact held-out error, ``refined_model.json``;
6. :func:`document` and :func:`write_outputs`: ``diagnosis.json``, ``report.html``.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ..errors import CliError
from ..ident import refined
from ..ident.base import fit_base, history_holdout
from ..ident.terms import TERMS, VOCABULARY
from ..io.modelfile import make_provenance, save_model
from ..io.recording import load_recording, sensor_session, session_start
from . import locate as loc
from . import significance as sg
from . import static_map
from .discriminate import calibration_band_hz, separation_doc
from .misfit import BANDS, band_energy, base_misfit
from .select import CHECKED_TERMS, FURTHER_RATIO_MAX, Ctx, make_masks, make_signals, select, simulate_refined

__all__ = ["diagnose", "DEFAULTS", "load", "fit_base_model", "locate", "refine", "document"]

DEFAULTS = {"settle_s": 0.5, "max_terms": 4, "block_s": 1.0, "max_rows": 120_000}
OUT_MARGIN = 0.05   # of the calibrated drive span
OUT_GUARD_S = 0.1   # [s] after the drive comes back into the calibrated range


def load(calibration, recordings):
    """(calibration recordings, recordings, names) loaded and checked: one sample rate, unique names."""
    cal = [load_recording(p) for p in calibration]
    recs = [load_recording(p) for p in recordings]
    rates = [(str(p), r.sample_rate_hz) for p, r in zip(list(calibration) + list(recordings), cal + recs)]
    f0 = rates[0][1]
    for p, f in rates:
        if abs(f / f0 - 1) > 0.01:
            raise CliError(f"diagnose: all recordings must share one sample rate: {rates[0][0]} is sampled at "
                           f"{f0:g} Hz, {p} at {f:g} Hz")
    names = [os.path.basename(p) for p in recordings]
    if len(set(names)) != len(names):
        names = [str(p) for p in recordings]
    return cal, recs, names


def fit_base_model(cal, calibration, settle_s, out, log, t_start, block_s=DEFAULTS["block_s"]):
    """The base model fitted on the calibration, written as ``base_model.json``: (params, base_info).
    ``base_info["misfit"]``: the base's error on calibration histories it did not see (``misfit.py``)."""
    base = fit_base(cal, settle_s=settle_s, holdout=True)
    base_info = base.pop("base_info")
    held = history_holdout(base)
    k0 = [min(int(round(settle_s / r.dt)), len(r) // 2) for r in cal]   # as locate's cal_k0
    base_info["misfit"] = base_misfit(held, [os.path.basename(str(p)) for p in calibration], cal[0].dt, 1.0 / block_s,
                                      edge_hz=calibration_band_hz(cal, k0))
    if base_info["misfit"] is not None:   # round 26: what that misfit leaves where a static map acts
        base_info["misfit"]["common_um2"] = static_map.common_misfit(held, [r.u for r in cal], [r.y for r in cal])
    prov = make_provenance(list(calibration), {"settle_s": settle_s}, rows=[len(r) for r in cal],
                           metrics={"dynamics_order": base_info["dynamics_order"], "plane": {
                               k: v for k, v in base_info["plane"].items() if k != "cv_table"}})
    save_model(out / "base_model.json", "refined", base, prov)
    pl = base_info["plane"]
    mf = base_info["misfit"]
    log(f"base model: plane {pl['plays']} plays x {pl['knots']} knots"
        f"{' + Bouc-Wen' if pl.get('bouc_wen') else ''}, dynamics order {base_info['dynamics_order']} "
        f"({time.perf_counter() - t_start:.1f} s)" + (
            f"; on held-out calibration histories {mf['rms_um']:.4f} um RMS (level "
            f"{np.sqrt(mf['mse_um2']['level']):.4f}, slow {np.sqrt(mf['mse_um2']['slow']):.4f}, fast "
            f"{np.sqrt(mf['mse_um2']['fast']):.4f} beyond noise {mf['noise_rms_um']:.4f})" if mf else ""))
    return base, base_info


def _outside_mask(s, lo, hi):
    """Samples where the drive is outside ``[lo, hi]`` (plus a margin) or left it within ``OUT_GUARD_S``."""
    m = OUT_MARGIN * (hi - lo)
    out = (s.u > hi + m) | (s.u < lo - m)
    if not np.any(out):
        return out
    g = max(1, int(round(OUT_GUARD_S / s.dt)))
    c = np.cumsum(out.astype(int))
    prev = np.concatenate([np.zeros(g, int), c[:-g]]) if c.size > g else np.zeros(c.size, int)
    return (c - prev) > 0


def _cut(s, v):
    import dataclasses
    return dataclasses.replace(s, t=s.t[v], u=s.u[v], y=s.y[v], u2=None if s.u2 is None else s.u2[v],
                               x2=None if s.x2 is None else s.x2[v], temp=None if s.temp is None else s.temp[v],
                               v=s.v[v], h=s.h[v], hyst=s.hyst[v], yb=s.yb[v], ydyn=s.ydyn[v])


def excursions(sigs, lo, hi):
    """Per recording, the drive's excursion beyond the calibrated drive range ``[lo, hi]`` [V] (0 inside), for
    :func:`select.make_masks`; None when no recording leaves the range by more than the outside report's margin
    (``OUT_MARGIN`` of its span): a drive that passes the edge by a rounding (dev nulls s124-023, s124-032: about
    1e-3 V) holds nothing a term beyond the edge could be tested on, and keeps the alternate blocks."""
    margin = OUT_MARGIN * (hi - lo)
    if not any(np.any((s.u > hi + margin) | (s.u < lo - margin)) for s in sigs):
        return None
    return [np.maximum(s.u - hi, 0.0) + np.maximum(lo - s.u, 0.0) for s in sigs]


def locate(base, cal, recs, names, settle_s, block_s, misfit=None, dynamics_band_hz=None):
    """The context of the current model on the recordings and the residual analysis (``dynamics_band_hz``: the
    band the base states its dynamics identified in, ``base_info``; a mode is offered only above it).

    Returns
    -------
    (ctx, located, outside_doc)
        The selection's context, ``located`` (locate.py's analysis of the base residual) and the report on
        samples outside the calibrated drive range (None when there are none).
    """
    sigs = make_signals(base, recs, names)
    cal_k0 = [min(int(round(settle_s / r.dt)), len(r) // 2) for r in cal]   # settled start per calibration file
    cal_u_lo = min(float(np.min(r.u[k0:])) for r, k0 in zip(cal, cal_k0))
    cal_u_hi = max(float(np.max(r.u[k0:])) for r, k0 in zip(cal, cal_k0))
    # round 20: the blocks beyond the calibrated range shared between the folds by their excursion (make_masks)
    valid, fold, block = make_masks(sigs, settle_s, block_s, excursions(sigs, cal_u_lo, cal_u_hi))
    dt = sigs[0].dt
    yv = np.concatenate([s.y[v] for s, v in zip(sigs, valid)])
    uv = np.concatenate([s.u[v] for s, v in zip(sigs, valid)])
    if yv.size < 16:
        raise CliError(f"diagnose: the recordings have {yv.size} samples after the first {settle_s:g} s; "
                       "nothing to diagnose")
    span = float(np.ptp(yv)) or 1.0
    resid = [s.y - s.yb for s in sigs]
    u2c = [r.u2 for r in cal if r.u2 is not None]
    ctx = Ctx(base=base, signals=sigs, valid=valid, fold=fold, block=block, names=names, n_rec=len(sigs), dt=dt,
              duration=max(s.t[-1] - s.t[0] for s in sigs),
              u2_ref=float(np.mean(np.concatenate(u2c))) if u2c else 0.0,
              y_center=0.5 * (float(yv.max()) + float(yv.min())), y_half=max(0.5 * span, 1e-9),
              u_lo=float(uv.min()), u_hi=float(uv.max()),
              u_mid_all=0.5 * (float(uv.max()) + float(uv.min())),
              u_half_all=max(0.5 * float(np.ptp(uv)), 1e-9),
              max_step=max(float(np.max(np.abs(np.diff(s.u)))) for s in sigs),
              peak_freqs=loc.peak_frequencies([r[v] for r, v in zip(resid, valid)], dt), y_span=span,
              mode_freqs=_mode_freqs(base, sigs, valid, cal, cal_k0, dt, dynamics_band_hz),
              cal_band_hz=calibration_band_hz(cal, cal_k0),
              dynamics_band_hz=None if dynamics_band_hz is None else float(dynamics_band_hz),
              cal=cal, cal_h=[refined.simulate_parts(base, r.t, r.u)["h"] for r in cal], cal_k0=cal_k0,
              cal_u_lo=cal_u_lo, cal_u_hi=cal_u_hi,
              misfit=misfit, **_drift_clock(cal, recs), **_offset_groups(cal, recs))
    # samples where the drive is (or within OUT_GUARD_S was) outside the calibrated range: the base model
    # extrapolates there. They stay in the selection - saturation or a sensor's curvature may show only there -
    # and are reported on their own, so the user can weigh a finding that rests on them
    outside = [_outside_mask(s, ctx.cal_u_lo, ctx.cal_u_hi) for s in sigs]
    out_v = np.concatenate([o[v] for o, v in zip(outside, valid)])
    ev = np.concatenate([r[v] for r, v in zip(resid, valid)])
    outside_doc = None
    if np.any(out_v):
        rin = float(np.sqrt(np.mean(ev[~out_v] ** 2))) if np.any(~out_v) else None
        rout = float(np.sqrt(np.mean(ev[out_v] ** 2)))
        outside_doc = {"calibrated_drive_v": [ctx.cal_u_lo, ctx.cal_u_hi], "fraction_of_samples": float(np.mean(out_v)),
                       "residual_rms_outside_um": rout, "residual_rms_inside_um": rin,
                       "evidence": (f"{100 * np.mean(out_v):.1f} % of the samples have the drive outside the calibrated "
                                    f"range {ctx.cal_u_lo:.1f}..{ctx.cal_u_hi:.1f} V (or left it less than "
                                    f"{OUT_GUARD_S:g} s before); the base model extrapolates there (residual RMS "
                                    f"{rout:.4f} um against {rin if rin is not None else float('nan'):.4f} um "
                                    "inside); a term found there rests on the base model's extrapolation.")}
    located = loc.locate([_cut(s, v) for s, v in zip(sigs, valid)], [r[v] for r, v in zip(resid, valid)], dt)
    return ctx, located, outside_doc


def _mode_freqs(base, sigs, valid, cal, cal_k0, dt, dynamics_band_hz=None) -> list | None:
    """Where ``unmodeled_resonance`` is offered (round 12, ``Ctx.mode_freqs``): the residual transfer's significant
    peak (``signature.mode_frequencies``) when it lies above the band the dynamics were identified in (the term's
    signature: a mode above that band; inside it G was fitted and a peak there is the base's misfit) and outside a
    notch of the base's own dynamics; None without a transfer estimate (then the residual spectrum's peaks).

    That band is the calibration's (99 % of its drive rate's energy) and, round 14, at least the band the base
    states it identified its dynamics in (``dynamics_band_hz``, twice the band of its H increments): development
    null s112-032 (KP, half length) was named ``unmodeled_resonance`` at 301 Hz, its stage's own main mode (304 Hz),
    above the calibration's 290 Hz but inside the 539 Hz the base's G was identified in. The rule is the round-12
    rule with the base's own statement of its band; it was chosen after reading that case."""
    from .signature import mode_frequencies, model_notches, transfer
    tr = transfer([s.yb[v] for s, v in zip(sigs, valid)], [s.y[v] for s, v in zip(sigs, valid)], dt)
    f_min = max(80.0, calibration_band_hz(cal, cal_k0), float(dynamics_band_hz or 0.0))
    return mode_frequencies(tr, f_min=f_min, notches=model_notches(base["dynamics"]["b"], dt))


def _drift_clock(cal, recs) -> dict:
    """``drift_t0`` (the end of the calibration on the session clock [s]) and ``drift_span`` (from it to the end
    of the last recording [s]) when every recording carries ``session_time_s``; else none (per-recording clock)."""
    starts = [session_start(r) for r in list(cal) + list(recs)]
    if not starts or any(s is None for s in starts):
        return {}
    ends = [s + float(r.t[-1] - r.t[0]) for s, r in zip(starts, list(cal) + list(recs))]
    t0 = max(ends[:len(cal)]) if cal else min(starts)
    return {"drift_t0": t0, "drift_span": max(max(ends) - t0, 0.0)}


def _offset_groups(cal, recs) -> dict:
    """The sensor zero's columns (``Ctx.offset_group``): when every recording carries ``session``, one constant per
    session other than the calibration's (a sensor's zero is a property of the session: recordings of one session
    share it, and the calibration's session has the base's); else none (a constant per recording)."""
    labels = [sensor_session(r) for r in list(cal) + list(recs)]
    if not labels or any(x is None for x in labels):
        return {}
    cal_labels = set(labels[:len(cal)])
    sessions = []
    for x in labels[len(cal):]:
        if x not in cal_labels and x not in sessions:
            sessions.append(x)
    return {"offset_group": [-1 if x in cal_labels else sessions.index(x) for x in labels[len(cal):]],
            "offset_sessions": sessions}


def _nrmse_pooled(ys, yhats, masks, span):
    e = np.concatenate([(yh - y)[m] for y, yh, m in zip(ys, yhats, masks)])
    return float(np.sqrt(np.mean(e ** 2)) / span) if e.size else float("nan")


def refine(ctx, ctx_all, fctx, recs, names, calibration, recordings, cal, settle_s, out):
    """The refined model (the accepted terms fitted on all settled data, in order), written as
    ``refined_model.json``, and the fit figures: (fit, refined model output, held-out prediction) per recording.

    The exact held-out figure: the terms fitted on one fold (in the order accepted), the refined model
    simulated and scored on the other fold."""
    ref = ctx_all.base
    terms = dict(ref.get("terms", {}))
    prov_r = make_provenance(list(calibration) + list(recordings), {"settle_s": settle_s},
                             rows=[len(r) for r in cal + recs], metrics={"terms": list(terms)})
    save_model(out / "refined_model.json", "refined", ref, prov_r)
    valid, fold, span = ctx.valid, ctx.fold, ctx.y_span
    ys = [r.y for r in recs]
    yb_all = [s.yb for s in ctx.signals]
    yr_all = simulate_refined(ref, recs, names) if terms else yb_all
    held_pred = [np.array(y, copy=True) for y in yb_all]
    if terms:
        for f in (0, 1):
            pf = simulate_refined(fctx[f].base, recs, names)
            for i, (p, fm) in enumerate(zip(pf, fold)):
                sel = fm == 1 - f
                held_pred[i][sel] = p[sel]

    def per(yh):
        return {n: _nrmse_pooled([y], [h], [v], float(np.ptp(y[v])) or 1.0) for n, y, h, v in zip(names, ys, yh, valid)}

    fit = {"nrmse_definition": "RMS(simulated - measured) / (max - min of measured), pooled over the "
                               f"recordings after the first {settle_s:g} s",
           "base": {"nrmse": _nrmse_pooled(ys, yb_all, valid, span), "per_recording": per(yb_all)},
           "refined": {"nrmse": _nrmse_pooled(ys, yr_all, valid, span), "per_recording": per(yr_all)},
           "heldout": {"base_nrmse": _nrmse_pooled(ys, yb_all, valid, span),
                       "refined_nrmse": _nrmse_pooled(ys, held_pred, valid, span),
                       "method": "terms fitted on alternate time blocks, refined model simulated, scored on the "
                                 "other blocks (2-fold)"}}
    return fit, yr_all, held_pred


def residual_bands(ctx) -> dict:
    """The base residual on the recordings per band of ``misfit.py`` (RMS [um] over the settled samples), to
    set beside the base's misfit on held-out calibration histories."""
    e = np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])
    rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(ctx.valid)])
    f = ctx.misfit["slow_hz"] if ctx.misfit else 1.0 / DEFAULTS["block_s"]
    en = band_energy(e, rec, ctx.dt, f) / max(e.size, 1)
    return {"rms_um": float(np.sqrt(np.mean(e ** 2))) if e.size else 0.0,
            **{f"{b}_rms_um": float(np.sqrt(x)) for b, x in zip(BANDS, en)}}


def _unidentified_text(last, base_info, where) -> str:
    """The band the base's dynamics were not identified in (above the calibration's), and the candidates whose
    signature check failed, for the `none` verdict; fills ``where["unidentified_band_hz"]`` and
    ``where["signature_failed"]``."""
    fb = base_info.get("identified_band_hz")
    if fb is None:
        return ""
    where["unidentified_band_hz"] = [fb, base_info.get("nyquist_hz")]
    text = (f" The base's dynamics were identified below {fb:.0f} Hz (the calibration's band); above it the data "
            "say nothing about them, and a drive-side term whose evidence lies there is named only when the "
            "residual's transfer has its shape.")
    failed = [c for c in last if c.signature_check is not None and not c.signature_check["passed"]]
    if failed:
        where["signature_failed"] = [{"name": c.name, **c.signature_check} for c in failed]
        text += " Refused by their signature check: " + "; ".join(
            f"{c.name} ({c.signature_check['reason']})" for c in failed) + "."
    return text


def _none_entry(last, fit, outside_doc, base_info, bands=None):
    best = last[0] if last else None
    dyn = base_info.get("dynamics_note", "")
    text = ("No candidate term lowers the held-out error enough: the best, "
            f"{best.name}, changes the held-out NRMSE from {best.nrmse_before:.4f} to {best.nrmse_after:.4f} "
            f"(p = {best.p:.1e}" + (f"; {best.veto}" if best.veto else "") + "); what is left is the base model's "
            f"own approximation error and noise (held-out NRMSE {fit['base']['nrmse']:.4f}; {dyn})."
            if best else "No candidate term applies.")
    mf = base_info.get("misfit")
    where = {}
    if bands:
        where["residual"] = bands
        text += (f" The base's residual on the recordings: {bands['rms_um']:.4f} um RMS (level "
                 f"{bands['level_rms_um']:.4f}, slow {bands['slow_rms_um']:.4f}, fast {bands['fast_rms_um']:.4f}).")
    if mf:
        where["base_misfit"] = {"rms_um": mf["rms_um"], "rms_seen_um": mf["rms_seen_um"],
                                **{f"{b}_rms_um": float(np.sqrt(mf["mse_um2"][b])) for b in BANDS}}
        text += (f" On calibration histories it did not see the base is off by {mf['rms_um']:.4f} um RMS against "
                 f"{mf['rms_seen_um']:.4f} um on the same samples seen; the excess by band: level "
                 f"{np.sqrt(mf['mse_um2']['level']):.4f}, slow {np.sqrt(mf['mse_um2']['slow']):.4f}, fast "
                 f"{np.sqrt(mf['mse_um2']['fast']):.4f} um.")
    if outside_doc:
        text += " " + outside_doc["evidence"]
        where["outside_calibrated_range"] = outside_doc
    text += _unidentified_text(last, base_info, where)
    return {"name": "none", "significant": False, "evidence": text, "where": where, "params": {},
            "improvement": {"nrmse_before": fit["base"]["nrmse"], "nrmse_after": fit["base"]["nrmse"]}}


def _branch_common_text(whole) -> str:
    """The evidence's sentence for a sensor curve judged on the branch-common part (round 19, static_map.py)."""
    bc = whole["branch_common"]
    return (f" Its fold ratios and p are those of the part of the residual every branch shares at equal displacement "
            f"(per bin of the output, the mean over the branches that visit it; {bc['n_bins']} held-out bins, "
            f"{bc['before_um']:.4f} -> {bc['after_um']:.4f} um; p of a one-sided paired t-test on the bins; credited "
            f"beyond the base's misfit on calibration histories it did not see, {bc['credited_ratio']:.2f}): on the "
            f"whole residual, beside the base's misfit on histories the calibration did not show, they were "
            f"{whole['fold_ratios'][0]:.2f}/{whole['fold_ratios'][1]:.2f}, p = {whole['p']:.1e}, credited ratio "
            f"{whole['credited_ratio']:.2f}.")


def document(ctx, accepted, rounds, fit, located, outside_doc, base_info, calibration, recordings):
    """The diagnosis document (diagnosis.json's content)."""
    effects = []
    for a in accepted:
        params, phrase = a.described
        sep_fields, sep_text = separation_doc(a.name, a.separation)
        where = loc.where_of([_cut(s, v) for s, v in zip(ctx.signals, ctx.valid)],
                             [x[v] for x, v in zip(a.contrib, ctx.valid)], ctx.dt)
        effects.append({
            "name": a.name, "significant": True,
            "evidence": (f"{phrase[0].upper() + phrase[1:]}; adding it to the model "
                         # round 23: a map of the reading may pass per recording with the pooled error not lower
                         + ("lowers" if a.exact_after < a.exact_before else "changes")
                         + f" the exact held-out NRMSE from {a.exact_before:.4f} to {a.exact_after:.4f}"
                         + (f", above {a.exact_above['above_hz']:.0f} Hz, where it acts, from "
                            f"{a.exact_above['nrmse_before']:.4f} to {a.exact_above['nrmse_after']:.4f}"
                            if a.exact_above else "")
                         + (f", beyond each recording's level (the state the history before it left), from "
                            f"{a.exact_beyond_level['nrmse_before']:.4f} to {a.exact_beyond_level['nrmse_after']:.4f}"
                            if a.exact_beyond_level else "") + " (active-block t and signed-rank tests on "
                         f"the linearized term, nested against a refit of the base's hysteresis, p = {a.p:.1e}, "
                         f"threshold {a.p_max:.1e})." + (f" {a.discrimination}" if a.discrimination else "")
                         + (f" Named in round {a.selection_round}, beside the terms before it: its fold ratios "
                            f"{a.fold_ratios[0]:.2f}/{a.fold_ratios[1]:.2f} and credited ratio {a.credited:.2f} are "
                            f"above the first round's {sg.RATIO_MAX} but below {a.ratio_max:g}, and its signature holds."
                            if a.below_gates else "")
                         + (_branch_common_text(a.whole) if a.whole and "branch_common" in a.whole else "")
                         + (f" Caution: the refined model is worse on {a.worsened[0]} (held-out error x"
                            f"{a.worsened[1]:.2f} there): where it is wrong, this model does not hold."
                            if a.worsened else "") + (f" {sep_text}" if sep_text else "")),
            "where": where, "params": params,
            "improvement": {"nrmse_before": a.exact_before, "nrmse_after": a.exact_after,
                            "exact_fold_ratios": a.exact_fold_ratios,
                            "linearized": {"nrmse_before": a.nrmse_before, "nrmse_after": a.nrmse_after},
                            "fold_ratios": a.fold_ratios, "p_value": a.p, "delta_bic": a.dbic,
                            "credited_ratio": a.credited, "credited_bands": a.credited_bands,
                            "selection_round": a.selection_round, "ratio_max": a.ratio_max,
                            "worse_on": ({"recording": a.worsened[0], "factor": a.worsened[1]}
                                         if a.worsened else None),
                            **({"slow_signature": a.slow_signature} if a.slow_signature else {}),
                            **({"whole_residual": a.whole} if a.whole else {}),
                            **({"exact_above": a.exact_above} if a.exact_above else {}),
                            **({"exact_beyond_level": a.exact_beyond_level} if a.exact_beyond_level else {})},
            "signature": a.term.signature, "signature_check": a.signature_check, **sep_fields})
    last = rounds[-1] if rounds else []
    named = {x["name"] for x in effects}
    if not effects:
        effects.append(_none_entry(last, fit, outside_doc, base_info, residual_bands(ctx)))
    for c in last:
        if c.name in named:
            continue
        effects.append({"name": c.name, "significant": False,
                        "evidence": (("Not accepted: " + c.veto + "; " if c.veto else "Not significant: ")
                                     + f"linearized held-out NRMSE {c.nrmse_before:.4f} -> {c.nrmse_after:.4f} "
                                     f"(fold ratios {c.fold_ratios[0]:.2f}, {c.fold_ratios[1]:.2f}; p = {c.p:.1e}; "
                                     f"dBIC {c.dbic:.0f})."),
                        "where": {}, "params": {},
                        # not added: the model (and its error) is unchanged; the candidate's own figures follow
                        "improvement": {"nrmse_before": c.nrmse_before, "nrmse_after": c.nrmse_before,
                                        "candidate": {"nrmse_after": c.nrmse_after,
                                                      "exact_fold_ratios": c.exact_fold_ratios,
                                                      **({"exact_above": c.exact_above} if c.exact_above else {})},
                                        "credited_ratio": c.credited, "credited_bands": c.credited_bands,
                                        "selection_round": c.selection_round, "ratio_max": c.ratio_max,
                                        "fold_ratios": c.fold_ratios, "p_value": c.p, "delta_bic": c.dbic,
                                        **({"slow_signature": c.slow_signature} if c.slow_signature else {}),
                                        **({"whole_residual": c.whole} if c.whole else {})},
                        "signature": c.term.signature, "signature_check": c.signature_check})
    return {"format": "piezoctl-diagnosis", "version": 1,
            "named": [x["name"] for x in effects if x["significant"]] or ["none"],
            "inseparable": [[x["name"]] + [a["name"] for a in x.get("alternatives", [])]
                            for x in effects if x["significant"] and x.get("alternatives")],
            "effects": effects,
            "base_model": "base_model.json", "refined_model": "refined_model.json",
            "fit": fit,
            "test": {"statement": "a term is significant when, fitted on alternate ~1 s time blocks and scored on "
                                  "the others (2-fold), jointly with free gains on the current model's hysteresis "
                                  "channels (a nested test: the model without the term has those gains refitted on "
                                  "the same fold), it lowers the held-out NRMSE to at most "
                                  f"{sg.RATIO_MAX} of the model without it in each fold; a one-sided t-test and a "
                                  "Wilcoxon signed-rank test (p = 2 x the smaller) on the log ratios "
                                  "log(MSE before / MSE after) of test units (parts of the blocks at least "
                                  f"{sg.UNIT_TAUS:g} correlation times of the residual's and the correction's energy "
                                  f"and {sg.UNIT_MIN_S:g} s long; blocks as clusters: a cluster-robust t-test and a "
                                  "signed-rank test with the same design effect; the same test on the blocks as "
                                  "well, p = 2 x the smaller) over the units where the term's "
                                  f"held-out predicted correction has at least {sg.ACTIVE_FRAC:g} of its "
                                  f"{sg.ACTIVE_PCT:g}th-percentile unit RMS (chosen without the test fold's "
                                  "measurements) gives p < "
                                  f"{sg.ALPHA:g} / (number of candidates in the round) (Bonferroni: family-wise "
                                  "error 1 % per round); and the BIC with the autocorrelation-corrected sample size "
                                  "decreases; and its improvement, less per band (level, slow, fast) the base's "
                                  "misfit on held-out calibration histories (base_info.misfit), still gives a ratio "
                                  f"of at most {sg.RATIO_MAX}; and the refined model, simulated exactly with the term fitted on one "
                                  "fold, lowers the error on the other fold in each (a term sized above an edge, a mode: also above that "
                                  "edge). After the first term, a term with a "
                                  "signature test of its own (" + ", ".join(CHECKED_TERMS) + ") is tested with both ratios "
                                  f"below {FURTHER_RATIO_MAX:g} instead of {sg.RATIO_MAX} (at the round's level: Holm's "
                                  "step-down over the remaining candidates); when it passes only so, its signature must "
                                  "hold (a slow signature at alpha / 3, a drive-side transfer check that can test it); "
                                  "after the first term every candidate is also nested against the accepted terms' "
                                  "own flexibility (a free gain on each and the change to its setting's grid "
                                  "neighbours, refitted on the same fold)",
                     "ratio_max": sg.RATIO_MAX, "ratio_max_further": FURTHER_RATIO_MAX,
                     "further_checked_terms": list(CHECKED_TERMS), "alpha_family": sg.ALPHA, "active_fraction": sg.ACTIVE_FRAC,
                     "unit_correlation_times": sg.UNIT_TAUS, "unit_min_s": sg.UNIT_MIN_S},
            "outside_calibrated_range": outside_doc,
            "base_info": base_info,
            "located": located,
            "calibration": list(map(str, calibration)), "recordings": list(map(str, recordings)),
            "time_s": None}


def write_outputs(doc, out, ctx, yr_all, held_pred, report, png, t_start):
    """Write diagnosis.json (and report.html with its figures)."""
    doc["time_s"] = round(time.perf_counter() - t_start, 2)
    if report:
        from .report import write_report
        write_report(out / "report.html", doc, ctx.signals, ctx.valid, yr_all, held_pred,
                     png_dir=out / "plots" if png else None)
        doc["time_s"] = round(time.perf_counter() - t_start, 2)
    with open(out / "diagnosis.json", "w") as fh:
        json.dump(_jsonable(doc), fh, indent=1, allow_nan=False)


def diagnose(calibration, recordings, out_dir, settle_s=DEFAULTS["settle_s"], max_terms=DEFAULTS["max_terms"],
             block_s=DEFAULTS["block_s"], report=True, log=print, png=False) -> dict:
    """Run the whole diagnosis and write ``diagnosis.json``, the model files and ``report.html``.

    Parameters
    ----------
    calibration, recordings : list of str
        Recording CSV files: calibration (fits the base model) and the recordings to explain.
    out_dir : str
        Output directory (created). The command (``commands/diagnose.py``) passes a temporary directory
        that it publishes only when the diagnosis succeeded.
    settle_s : float
        Seconds [s] at the start of each recording left out of every fit and score.
    max_terms : int
        At most this many terms are added.
    block_s : float
        Length [s] of the cross-validation blocks (at least 6 per recording).
    report : bool
        Write report.html.
    png : bool
        Also write the report's figures as ``out_dir/plots/*.png``.

    Returns
    -------
    dict
        The diagnosis document (as written).
    """
    t_start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cal, recs, names = load(calibration, recordings)
    base, base_info = fit_base_model(cal, calibration, settle_s, out, log, t_start, block_s)
    ctx, located, outside_doc = locate(base, cal, recs, names, settle_s, block_s, base_info.get("misfit"),
                                       base_info.get("dynamics_band_hz"))
    fold_all = np.concatenate([f[v] for f, v in zip(ctx.fold, ctx.valid)])
    block_all = np.concatenate([b[v] for b, v in zip(ctx.block, ctx.valid)])
    e = np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])
    log(f"residual analysis done ({time.perf_counter() - t_start:.1f} s); base held-out NRMSE "
        f"{np.sqrt(np.mean(e ** 2)) / ctx.y_span:.4f}")
    f_band = calibration_band_hz(cal, ctx.cal_k0)   # the band the base's dynamics were identified in [Hz]
    fc_hp = min(3.0 * f_band, 0.1 / ctx.dt)
    accepted, rounds, ctx_all, fctx = select(ctx, [TERMS[n] for n in VOCABULARY], recs, fold_all, block_all,
                                             max_terms, DEFAULTS["max_rows"], fc_hp, log, f_band=f_band)
    base_info["identified_band_hz"] = f_band
    base_info["nyquist_hz"] = 0.5 / ctx.dt
    log(f"selection done ({time.perf_counter() - t_start:.1f} s): {[a.name for a in accepted] or ['none']}")
    fit, yr_all, held_pred = refine(ctx, ctx_all, fctx, recs, names, calibration, recordings, cal, settle_s, out)
    doc = document(ctx, accepted, rounds, fit, located, outside_doc, base_info, calibration, recordings)
    # flagged, not acted on: a jump the stage could not follow (a recorder's reset) or a step drive
    doc["drive_discontinuities"] = loc.discontinuities_doc(calibration, cal, recordings, recs)
    write_outputs(doc, out, ctx, yr_all, held_pred, report, png, t_start)
    return doc


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if np.isfinite(v) else (1e300 if v > 0 else -1e300) if not np.isnan(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x
