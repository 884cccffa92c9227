"""The diagnosis: base model, residual analysis, forward selection of terms with a
cross-validated significance test, refined model, diagnosis.json and report.html."""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

from ..errors import CliError
from ..ident import refined
from ..io.modelfile import make_provenance, save_model
from ..io.recording import load_recording
from . import locate as loc
from . import significance as sg
from ..dsp import filt
from ..ident.base import fit_base
from ..models.hysteresis import hysteresis_channels
from .effects import EFFECTS, VOCABULARY, Signals, nuisance_columns
from .discriminate import calibration_band_hz, discriminate_group, highpassed

__all__ = ["diagnose", "DEFAULTS"]

DEFAULTS = {"settle_s": 0.5, "max_terms": 4, "block_s": 1.0, "max_rows": 120_000}


@dataclasses.dataclass
class Ctx:
    base: dict
    signals: list
    valid: list          # bool masks (settled samples)
    fold: list           # 0/1 per sample (-1: not used)
    block: list          # global block id per sample
    names: list
    n_rec: int
    dt: float
    duration: float
    u2_ref: float
    y_center: float
    y_half: float
    u_lo: float
    u_hi: float
    u_mid_all: float
    u_half_all: float
    max_step: float
    peak_freqs: list
    y_span: float
    cal: list = dataclasses.field(default_factory=list)       # calibration recordings
    cal_h: list = dataclasses.field(default_factory=list)     # base H output on them [um]
    cal_k0: list = dataclasses.field(default_factory=list)    # settled start index per calibration recording
    refit_cache: dict = dataclasses.field(default_factory=dict)
    design_cache: dict = dataclasses.field(default_factory=dict)
    nuisance: np.ndarray | None = None   # hysteresis_nuisance() of this model, computed on first use
    cal_u_lo: float = 0.0     # calibrated drive range [V] (settled calibration samples)
    cal_u_hi: float = 0.0


def _signals(base, recs, names):
    out = []
    for i, (r, n) in enumerate(zip(recs, names)):
        p = refined.simulate_parts(base, r.t, r.u)
        off = float(base["hysteresis"].get("offset", 0.0))
        out.append(Signals(name=n, t=r.t, u=r.u, y=r.y, u2=r.u2, x2=r.x2, temp=r.temp, dt=r.dt, v=p["v"],
                           h=p["h"], hyst=p["hyst"], yb=p["y"], ydyn=p["y_dyn"] + off, index=i))
    return out


def _masks(sigs, settle_s, block_s):
    valid, fold, block = [], [], []
    nb = 0
    for s in sigs:
        n = s.t.size
        k0 = min(int(round(settle_s / s.dt)), n // 2)
        v = np.zeros(n, bool)
        v[k0:] = True
        m = n - k0
        nblk = int(np.clip(round(m * s.dt / block_s), 6, 40))
        b = np.full(n, -1)
        b[k0:] = np.minimum((np.arange(m) * nblk) // m, nblk - 1)
        f = np.where(b >= 0, b % 2, -1)
        block.append(np.where(b >= 0, b + nb, -1))
        nb += nblk
        valid.append(v)
        fold.append(f)
    return valid, fold, block


class _Design:
    """Stacked regressors of one effect setting over all recordings (settled samples)."""

    def __init__(self, ctx, eff, setting):
        self.eff, self.setting = eff, setting
        self.X = np.vstack([np.asarray(eff.regressors(ctx, s, setting), float)[v]
                            for s, v in zip(ctx.signals, ctx.valid)])
        self.k = self.X.shape[1]


def _lstsq(X, y):
    """Least squares on unit-RMS columns through the normal equations (the design is tall and narrow: a
    k x k solve instead of an SVD of the rows); rank deficiency is handled by the small solve's cutoff."""
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    Xs = X / sc
    th, *_ = np.linalg.lstsq(Xs.T @ Xs, Xs.T @ y, rcond=1e-12)
    return th / sc


def _lstsq_bounded(X, y, lb):
    """Least squares with lower bounds ``lb`` (-inf: free) on unit-RMS columns."""
    from scipy.optimize import lsq_linear
    sc = np.sqrt(np.mean(X ** 2, axis=0))
    sc[sc == 0] = 1.0
    sol = lsq_linear(X / sc, y, bounds=(np.asarray(lb, float) * sc, np.inf), method="bvls", lsq_solver="exact")
    return sol.x / sc


def _train_rows(train, rows):
    idx = np.flatnonzero(train)
    if idx.size > rows:
        idx = idx[:: int(np.ceil(idx.size / rows))]
    return idx


def _fit_predict(Xs, e, train, test, rows, lb=None, nuis=None):
    """Least squares of e on [Xs] over train rows (strided), coefficients >= ``lb`` when given; prediction on
    test rows. ``nuis``: the nested test's nuisance as (train rows, test rows) of its columns, prepended (its
    coefficients first, unbounded), sliced once per fold by the caller."""
    X = np.hstack(Xs) if len(Xs) > 1 else Xs[0]
    idx = _train_rows(train, rows)
    Xtr = X[idx] if nuis is None else np.hstack([nuis[0], X[idx]])
    if lb is not None and nuis is not None:
        lb = np.concatenate([np.full(nuis[0].shape[1], -np.inf), np.asarray(lb, float)])
    th = _lstsq(Xtr, e[idx]) if lb is None else _lstsq_bounded(Xtr, e[idx], lb)
    sse_tr = float(np.sum((e[idx] - Xtr @ th) ** 2)) * (np.sum(train) / max(idx.size, 1))
    if nuis is None:
        return th, X[test] @ th, sse_tr
    m = nuis[1].shape[1]
    return th, nuis[1] @ th[:m] + X[test] @ th[m:], sse_tr


def _design(ctx, eff, st):
    key = (eff.name, repr(st))
    if key not in ctx.design_cache:
        ctx.design_cache[key] = _Design(ctx, eff, st)
    return ctx.design_cache[key]


def _designs(ctx, eff):
    settings = eff.settings(ctx)
    return settings, [_design(ctx, eff, st) for st in settings]


def _best_setting(ctx, eff, e, train, test, rows, nuis=None):
    """(setting, design, sse on train, prediction on test, coefficients) with the least training error over the
    effect's grid, then over its finer settings around the best one (``Effect.refine``, twice). With ``nuis``
    (see :func:`_fit_predict`) the nuisance is fitted jointly and its coefficients are dropped from the result."""
    settings, designs = _designs(ctx, eff)
    lb = eff.lower(ctx)
    best = None
    level = {}   # refinement level at which each tried setting was proposed (grid: 0)
    new_level = 0
    for _ in range(3):
        for st, d in zip(settings, designs):
            if repr(st) in level:
                continue
            level[repr(st)] = new_level
            th, pa, sse = _fit_predict([d.X], e, train, test, rows, lb, nuis)
            if nuis is not None:
                th = th[nuis[0].shape[1]:]
            if best is None or sse < best[2]:
                best = (st, d, sse, pa, th)
        new_level = level[repr(best[0])] + 1
        settings = eff.refine(ctx, best[0], new_level) if new_level <= 2 else []
        if not settings:
            break
        designs = [_design(ctx, eff, st) for st in settings]
    return best


def hysteresis_nuisance(ctx):
    """The nested tests' nuisance (n_settled, m + 1): the current model's hysteresis channels through its
    dynamics (free gains on them refit the base's own flexibility on the new data: loop width per play
    threshold, the reversible curve's gain) and a constant, stacked over the settled samples; cached on the
    context."""
    if ctx.nuisance is None:
        hp = ctx.base["hysteresis"]
        b, a = ctx.base["dynamics"]["b"], ctx.base["dynamics"]["a"]
        ctx.nuisance = np.vstack([np.column_stack([filt(b, a, hysteresis_channels(hp, s.v)), np.ones(s.v.size)])[v]
                                  for s, v in zip(ctx.signals, ctx.valid)])
    return ctx.nuisance


def _residual(ctx):
    return np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])


def _evaluate(ctxs, eff, es, fold_all, block_all, rows, p_max):
    """Cross-validated evaluation of effect ``eff`` on top of the current model.

    ``ctxs[f]``, ``es[f]``: the model (terms accepted so far, fitted on fold f only) and its residual; the
    candidate is fitted on fold f of that residual and predicts fold 1 - f.
    """
    e_before = np.zeros(fold_all.size)
    pred_after = np.zeros(fold_all.size)
    chosen = []
    fold_ratios = []
    k = 1
    for f in (0, 1):
        ctx, e = ctxs[f], es[f]
        settings, designs = _designs(ctx, eff)
        nuis = nuisance_columns(eff, ctx, designs[0].k)
        k = max(d.k for d in designs) - len(nuis) + (1 if len(settings) > 1 else 0)
        train, test = fold_all == f, fold_all == 1 - f
        e_before[test] = e[test]
        N = None
        if eff.nested:   # nested against a refit of the current model's own hysteresis on this fold
            Nall = hysteresis_nuisance(ctx)
            N = (Nall[_train_rows(train, rows)], Nall[test])
        if nuis or N is not None:  # nested: "before" is the model with the nuisance columns alone refitted here
            Xn = [designs[0].X[:, nuis]] if nuis else [np.zeros((e.size, 0))]
            _, pn, _ = _fit_predict(Xn, e, train, test, rows, nuis=N)
            e_before[test] = e[test] - pn
        best = _best_setting(ctx, eff, e, train, test, rows, N)
        pred_after[test] = best[3] - (e[test] - e_before[test])
        chosen.append(best)
        rb = float(np.sqrt(np.mean(e_before[test] ** 2)))
        ra = float(np.sqrt(np.mean((e[test] - best[3]) ** 2)))
        fold_ratios.append(ra / rb if rb > 0 else 1.0)
    span = ctxs[0].y_span
    used = fold_all >= 0
    rb_res = e_before[used]
    ra_res = (e_before - pred_after)[used]
    nb = float(np.sqrt(np.mean(rb_res ** 2)) / span)
    na = float(np.sqrt(np.mean(ra_res ** 2)) / span)
    t, p, n_act = sg.active_block_test(rb_res, ra_res, pred_after[used], block_all[used])
    neff = sg.effective_n(rb_res)
    dbic = sg.bic_delta(float(np.sum(rb_res ** 2)), float(np.sum(ra_res ** 2)), neff, k)
    ratio = na / nb if nb > 0 else 1.0
    significant = bool(max(fold_ratios) <= sg.RATIO_MAX and p < p_max and dbic < 0)
    return {"effect": eff, "ratio": ratio, "fold_ratios": fold_ratios, "nrmse_before": nb, "nrmse_after": na,
            "t": t, "p": p, "n_active": n_act, "p_max": p_max, "dbic": dbic, "n_eff": neff, "significant": significant,
            "design": [c[1] for c in chosen], "setting": [c[0] for c in chosen], "coef": [c[4] for c in chosen],
            "veto": None}


def _model_params(base, terms):
    """``base`` (which may already have terms) with ``terms`` added; a drive-dynamics term brings its refitted G."""
    ref = dict(base)
    ref["terms"] = dict(base.get("terms", {}) or {})
    for k, v in terms.items():
        v = dict(v)
        dyn = v.pop("_dynamics", None)
        if dyn is not None:
            ref["dynamics"] = dyn
        hyst = v.pop("_hysteresis", None)
        if hyst is not None:
            ref["hysteresis"] = hyst
        ref["terms"][k] = v
    return ref


def _rebase(ctx, params, recs):
    """The context re-derived from ``params`` by exact simulation: every later candidate's signals (H output,
    hysteretic part, dynamics, output) come from the refined model, not from the base."""
    off = float(params["hysteresis"].get("offset", 0.0))
    po = params.get("terms", {}).get("sensor_offset")
    sigs = []
    for s, r in zip(ctx.signals, recs):
        p = refined.simulate_parts(params, r.t, r.u, r.u2)
        y = p["y"]
        if po is not None:
            y = y + po["per_recording"].get(s.name, po["offset_um"]) - po["offset_um"]
        sigs.append(dataclasses.replace(s, v=p["v"], h=p["h"], hyst=p["hyst"], yb=y, ydyn=p["y_dyn"] + off))
    cal_h = [refined.simulate_parts(params, r.t, r.u, r.u2)["h"] for r in ctx.cal]
    return dataclasses.replace(ctx, base=params, signals=sigs, cal_h=cal_h, refit_cache={}, design_cache={},
                               nuisance=None)


def _exact_fold(ctx, params, d, f, fold_all, recs):
    """Exact check of candidate ``d`` in fold f: its term (setting and coefficients fitted on fold f) added to the
    fold-f model, the recordings simulated, the error scored on fold 1 - f against the model without it."""
    eff = d["effect"]
    new = _model_params(params, {eff.name: eff.term(ctx, d["setting"][f], d["coef"][f])})
    ys = _simulate_refined(new, recs, ctx.names)
    e_new = np.concatenate([(s.y - y)[v] for s, y, v in zip(ctx.signals, ys, ctx.valid)])
    e_old = _residual(ctx)
    test = fold_all == 1 - f
    return {"params": new, "sse_before": float(np.sum(e_old[test] ** 2)), "sse_after": float(np.sum(e_new[test] ** 2)),
            "n": int(np.sum(test)), "ys": ys}


def _simulate_refined(params, recs, names):
    out = []
    off = params["terms"].get("sensor_offset")
    for r, n in zip(recs, names):
        y = refined.simulate(params, r.t, r.u, r.u2)
        if off is not None:  # per-recording offsets where the recording is known
            y = y + off["per_recording"].get(n, off["offset_um"]) - off["offset_um"]
        out.append(y)
    return out


def _nrmse_pooled(ys, yhats, masks, span):
    e = np.concatenate([(yh - y)[m] for y, yh, m in zip(ys, yhats, masks)])
    return float(np.sqrt(np.mean(e ** 2)) / span) if e.size else float("nan")


def diagnose(calibration, recordings, out_dir, settle_s=DEFAULTS["settle_s"], max_terms=DEFAULTS["max_terms"],
             block_s=DEFAULTS["block_s"], report=True, log=print, png=False) -> dict:
    """Run the whole diagnosis and write ``diagnosis.json``, the model files and ``report.html``.

    Parameters
    ----------
    calibration, recordings : list of str
        Recording CSV files: calibration (fits the base model) and the recordings to explain.
    out_dir : str
        Output directory (created).
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
    cal = [load_recording(p) for p in calibration]
    recs = [load_recording(p) for p in recordings]
    fs = {round(r.sample_rate_hz, 3) for r in cal + recs}
    if max(fs) / min(fs) - 1 > 0.01:
        raise CliError(f"diagnose: all recordings must share one sample rate (got {sorted(fs)} Hz)")
    names = [os.path.basename(p) for p in recordings]
    if len(set(names)) != len(names):
        names = [str(p) for p in recordings]
    base = fit_base(cal, settle_s=settle_s)
    base_info = base.pop("base_info")
    prov = make_provenance(list(calibration), {"settle_s": settle_s}, rows=[len(r) for r in cal],
                           metrics={"dynamics_order": base_info["dynamics_order"]})
    save_model(out / "base_model.json", "refined", base, prov)
    log(f"base model: dynamics order {base_info['dynamics_order']} ({time.perf_counter() - t_start:.1f} s)")

    sigs = _signals(base, recs, names)
    valid, fold, block = _masks(sigs, settle_s, block_s)
    dt = sigs[0].dt
    yv = np.concatenate([s.y[v] for s, v in zip(sigs, valid)])
    uv = np.concatenate([s.u[v] for s, v in zip(sigs, valid)])
    span = float(np.ptp(yv)) or 1.0
    resid = [s.y - s.yb for s in sigs]
    u2c = [r.u2 for r in cal if r.u2 is not None]
    du = max(float(np.max(np.abs(np.diff(s.u)))) for s in sigs)
    cal_h = [refined.simulate_parts(base, r.t, r.u)["h"] for r in cal]
    cal_k0 = [min(int(round(settle_s / r.dt)), len(r) // 2) for r in cal]   # settled start per calibration file
    ctx = Ctx(base=base, signals=sigs, valid=valid, fold=fold, block=block, names=names, n_rec=len(sigs), dt=dt,
              duration=max(s.t[-1] - s.t[0] for s in sigs),
              u2_ref=float(np.mean(np.concatenate(u2c))) if u2c else 0.0,
              y_center=0.5 * (float(yv.max()) + float(yv.min())), y_half=max(0.5 * span, 1e-9),
              u_lo=float(uv.min()), u_hi=float(uv.max()),
              u_mid_all=0.5 * (float(uv.max()) + float(uv.min())),
              u_half_all=max(0.5 * float(np.ptp(uv)), 1e-9), max_step=du,
              peak_freqs=loc.peak_frequencies([r[v] for r, v in zip(resid, valid)], dt), y_span=span,
              cal=cal, cal_h=cal_h, cal_k0=cal_k0,
              cal_u_lo=min(float(np.min(r.u[k0:])) for r, k0 in zip(cal, cal_k0)),
              cal_u_hi=max(float(np.max(r.u[k0:])) for r, k0 in zip(cal, cal_k0)))
    # samples where the drive is (or within OUT_GUARD_S was) outside the calibrated range: the base model
    # extrapolates there (hysteresis class and weights identified inside, the cubic continued as a line).
    # They stay in the selection - saturation or a sensor's curvature may show only there - and are reported
    # on their own, so the user can weigh a finding that rests on them
    outside = [_outside_mask(s, ctx.cal_u_lo, ctx.cal_u_hi) for s in sigs]
    out_v = np.concatenate([o[v] for o, v in zip(outside, valid)])
    outside_doc = None
    if np.any(out_v):
        ev = np.concatenate([r[v] for r, v in zip(resid, valid)])
        outside_doc = {"calibrated_drive_v": [ctx.cal_u_lo, ctx.cal_u_hi], "fraction_of_samples": float(np.mean(out_v)),
                       "residual_rms_outside_um": float(np.sqrt(np.mean(ev[out_v] ** 2))),
                       "residual_rms_inside_um": float(np.sqrt(np.mean(ev[~out_v] ** 2))) if np.any(~out_v) else None,
                       "evidence": (f"{100 * np.mean(out_v):.1f} % of the samples have the drive outside the calibrated "
                                    f"range {ctx.cal_u_lo:.1f}..{ctx.cal_u_hi:.1f} V (or left it less than "
                                    f"{OUT_GUARD_S:g} s before); the base model extrapolates there (residual RMS "
                                    f"{np.sqrt(np.mean(ev[out_v] ** 2)):.4f} um against "
                                    f"{np.sqrt(np.mean(ev[~out_v] ** 2)) if np.any(~out_v) else float('nan'):.4f} um "
                                    "inside); a term found there rests on the base model's extrapolation.")}
    e = np.concatenate([r[v] for r, v in zip(resid, valid)])
    fold_all = np.concatenate([f[v] for f, v in zip(fold, valid)])
    block_all = np.concatenate([b[v] for b, v in zip(block, valid)])
    located = loc.locate([_cut(s, v) for s, v in zip(sigs, valid)], [r[v] for r, v in zip(resid, valid)], dt)
    log(f"residual analysis done ({time.perf_counter() - t_start:.1f} s); base held-out NRMSE "
        f"{np.sqrt(np.mean(e ** 2)) / span:.4f}")

    rows = DEFAULTS["max_rows"]
    accepted = []
    rounds = []
    candidates = [EFFECTS[n] for n in VOCABULARY if EFFECTS[n].applicable(ctx)]
    # the current model: on all data (ctx_all, the refined model) and per fold (fctx[f]: the accepted terms
    # fitted on fold f only, the model whose held-out error on fold 1 - f is scored); after each accepted term
    # all three are re-derived by exact simulation of the refined model
    ctx_all, fctx = ctx, [ctx, ctx]
    fc_hp = min(3.0 * calibration_band_hz(cal, ctx.cal_k0), 0.1 / dt)
    for _ in range(max_terms):
        groups = {a["effect"].group for a in accepted if a["effect"].group}
        todo = [eff for eff in candidates if eff.name not in {a["effect"].name for a in accepted}
                and not (eff.group and eff.group in groups)]
        if not todo:
            break
        p_max = sg.ALPHA / max(len(todo), 1)
        es = [_residual(fctx[0])]
        es.append(es[0] if fctx[1] is fctx[0] else _residual(fctx[1]))
        evals = [_evaluate(fctx, eff, es, fold_all, block_all, rows, p_max) for eff in todo]
        evals.sort(key=lambda d: d["ratio"])
        # drive-side dynamics candidates that all pass: told apart by their exact residual above the
        # calibration's band (discriminate.py)
        dd = [d for d in evals if d["significant"] and d["effect"].group == "drive_dynamics"]
        if len(dd) > 1 and fc_hp > 0:
            hp = []
            for d in dd:
                d["exact"] = [_exact_fold(fctx[f], fctx[f].base, d, f, fold_all, recs) for f in (0, 1)]
                h = np.zeros(fold_all.size)
                for f in (0, 1):
                    sel = fold_all == 1 - f
                    h[sel] = highpassed(fctx[f], d["exact"][f]["ys"], fc_hp)[sel]
                hp.append(h)
            order, text = discriminate_group(dd, hp, fold_all, block_all, fc_hp)
            log("    " + text)
            pos = [i for i, d in enumerate(evals) if any(d is x for x in dd)]
            for i, k in zip(pos, order):
                evals[i] = dd[k]
            for d in dd:
                d["discrimination"] = text
        rounds.append(evals)
        best = None
        for d in evals:
            if not d["significant"] or d["veto"]:
                continue
            ex = d.get("exact") or [_exact_fold(fctx[f], fctx[f].base, d, f, fold_all, recs) for f in (0, 1)]
            d["exact_fold_ratios"] = [float(np.sqrt(x["sse_after"] / x["sse_before"])) if x["sse_before"] > 0
                                      else 1.0 for x in ex]
            n_ex = sum(x["n"] for x in ex)
            d["exact_before"] = float(np.sqrt(sum(x["sse_before"] for x in ex) / max(n_ex, 1)) / span)
            d["exact_after"] = float(np.sqrt(sum(x["sse_after"] for x in ex) / max(n_ex, 1)) / span)
            log(f"    exact {d['effect'].name}: {d['exact_fold_ratios']} {d['exact_before']:.4f} -> {d['exact_after']:.4f}")
            if max(d["exact_fold_ratios"]) < 1.0:
                d["exact"] = ex
                best = d
                break
            d["veto"] = ("the exact simulation of the refined model with this term does not lower the held-out "
                         f"error in each fold (ratios {d['exact_fold_ratios'][0]:.2f}, {d['exact_fold_ratios'][1]:.2f})")
        log("  " + ", ".join(f"{d['effect'].name} {d['ratio']:.3f} ({d['fold_ratios'][0]:.2f}/"
                             f"{d['fold_ratios'][1]:.2f} p {d['p']:.0e} n{d['n_active']})"
                             f"{'*' if d['significant'] and not d['veto'] else ''}{'V' if d['veto'] else ''}"
                             for d in evals[:6]))
        if best is None:
            break
        # setting and coefficients on all selection samples, applied to the all-data model
        allmask = fold_all >= 0
        e_all = _residual(ctx_all)
        Nall = hysteresis_nuisance(ctx_all) if best["effect"].nested else None
        st, dsg, sse, _, th = _best_setting(ctx_all, best["effect"], e_all, allmask, np.zeros(e_all.size, bool), rows,
                                            None if Nall is None else (Nall[_train_rows(allmask, rows)],
                                                                       Nall[:0]))
        bs = (st, dsg, sse, th)
        eff = best["effect"]
        best["setting_all"], best["coef_all"] = bs[0], bs[3]
        best["describe"] = eff.describe(ctx_all, bs[0], bs[3])
        c_term = np.array(bs[3], float)
        c_term[nuisance_columns(eff, ctx_all, c_term.size)] = 0.0  # where the term acts: its own columns only
        best["contrib"] = [np.asarray(eff.regressors(ctx_all, s, bs[0]), float) @ c_term for s in ctx_all.signals]
        params_all = _model_params(ctx_all.base, {eff.name: eff.term(ctx_all, bs[0], bs[3])})
        ctx_all = _rebase(ctx_all, params_all, recs)
        fctx = [_rebase(fctx[f], best["exact"][f]["params"], recs) for f in (0, 1)]
        accepted.append(best)
    log(f"selection done ({time.perf_counter() - t_start:.1f} s): "
        f"{[a['effect'].name for a in accepted] or ['none']}")

    # refined model: the accepted terms, each fitted on all settled data on top of the previous ones
    ref = ctx_all.base
    terms = dict(ref.get("terms", {}))
    prov_r = make_provenance(list(calibration) + list(recordings), {"settle_s": settle_s},
                             rows=[len(r) for r in cal + recs], metrics={"terms": list(terms)})
    save_model(out / "refined_model.json", "refined", ref, prov_r)
    ys = [r.y for r in recs]
    yb_all = [s.yb for s in sigs]
    yr_all = _simulate_refined(ref, recs, names) if terms else yb_all
    # exact held-out of the refined model: the terms fitted on one fold (in the order accepted), the refined
    # model simulated and scored on the other fold
    held_pred = [np.array(y, copy=True) for y in yb_all]
    if terms:
        for f in (0, 1):
            pf = _simulate_refined(fctx[f].base, recs, names)
            for i, (p, fm) in enumerate(zip(pf, fold)):
                sel = fm == 1 - f
                held_pred[i][sel] = p[sel]
    fit = {"nrmse_definition": "RMS(simulated - measured) / (max - min of measured), pooled over the "
                               f"recordings after the first {settle_s:g} s",
           "base": {"nrmse": _nrmse_pooled(ys, yb_all, valid, span),
                    "per_recording": {n: _nrmse_pooled([y], [yh], [v], float(np.ptp(y[v])) or 1.0)
                                      for n, y, yh, v in zip(names, ys, yb_all, valid)}},
           "refined": {"nrmse": _nrmse_pooled(ys, yr_all, valid, span),
                       "per_recording": {n: _nrmse_pooled([y], [yh], [v], float(np.ptp(y[v])) or 1.0)
                                         for n, y, yh, v in zip(names, ys, yr_all, valid)}},
           "heldout": {"base_nrmse": _nrmse_pooled(ys, yb_all, valid, span),
                       "refined_nrmse": _nrmse_pooled(ys, held_pred, valid, span),
                       "method": "terms fitted on alternate time blocks, refined model simulated, scored on the "
                                 "other blocks (2-fold)"}}
    effects = []
    for a in accepted:
        params, phrase = a["describe"]
        where = loc.where_of([_cut(s, v) for s, v in zip(sigs, valid)], [x[v] for x, v in zip(a["contrib"], valid)], dt)
        effects.append({
            "name": a["effect"].name, "significant": True,
            "evidence": (f"{phrase[0].upper() + phrase[1:]}; adding it to the model lowers the exact held-out NRMSE "
                         f"from {a['exact_before']:.4f} to {a['exact_after']:.4f} (active-block t and signed-rank tests on the "
                         f"linearized term p = {a['p']:.1e}, threshold {a['p_max']:.1e})."
                         + (f" {a['discrimination']}" if a.get("discrimination") else "")),
            "where": where, "params": params,
            "improvement": {"nrmse_before": a["exact_before"], "nrmse_after": a["exact_after"],
                            "exact_fold_ratios": a["exact_fold_ratios"],
                            "linearized": {"nrmse_before": a["nrmse_before"], "nrmse_after": a["nrmse_after"]},
                            "fold_ratios": a["fold_ratios"], "p_value": a["p"], "delta_bic": a["dbic"]},
            "signature": a["effect"].signature})
    last = rounds[-1] if rounds else []
    named = {x["name"] for x in effects}
    if not effects:
        best = last[0] if last else None
        effects.append({"name": "none", "significant": False,
                        "evidence": ("No candidate term lowers the held-out error enough: the best, "
                                     f"{best['effect'].name}, changes the held-out NRMSE from "
                                     f"{best['nrmse_before']:.4f} to {best['nrmse_after']:.4f} (p = {best['p']:.1e}); "
                                     "what is left is the base model's own approximation error and noise."
                                     + (" " + outside_doc["evidence"] if outside_doc else ""))
                        if best else "No candidate term applies.",
                        "where": {"outside_calibrated_range": outside_doc} if outside_doc else {}, "params": {},
                        "improvement": {"nrmse_before": fit["base"]["nrmse"], "nrmse_after": fit["base"]["nrmse"]}})
    for d in last:
        if d["effect"].name in named:
            continue
        effects.append({"name": d["effect"].name, "significant": False,
                        "evidence": (("Not accepted: " + d["veto"] + "; " if d["veto"] else "Not significant: ")
                                     + f"linearized held-out NRMSE {d['nrmse_before']:.4f} -> "
                                     f"{d['nrmse_after']:.4f} (fold ratios {d['fold_ratios'][0]:.2f}, "
                                     f"{d['fold_ratios'][1]:.2f}; p = {d['p']:.1e}; dBIC {d['dbic']:.0f})."),
                        "where": {}, "params": {},
                        # not added: the model (and its error) is unchanged; the candidate's own figures follow
                        "improvement": {"nrmse_before": d["nrmse_before"], "nrmse_after": d["nrmse_before"],
                                        "candidate": {"nrmse_after": d["nrmse_after"],
                                                      "exact_fold_ratios": d.get("exact_fold_ratios")},
                                        "fold_ratios": d["fold_ratios"], "p_value": d["p"], "delta_bic": d["dbic"]},
                        "signature": d["effect"].signature})
    doc = {"format": "piezoctl-diagnosis", "version": 1,
           "named": [x["name"] for x in effects if x["significant"]] or ["none"],
           "effects": effects,
           "base_model": "base_model.json", "refined_model": "refined_model.json",
           "fit": fit,
           "test": {"statement": "a term is significant when, fitted on alternate ~1 s time blocks and scored on "
                                 "the others (2-fold), it lowers the held-out NRMSE to at most "
                                 f"{sg.RATIO_MAX} of the model without it in each fold; a one-sided t-test and a Wilcoxon signed-rank test (p = 2 x the smaller) on the "
                                 "per-block log ratios log(MSE before / MSE after) over the blocks where the term's "
                                 "held-out predicted correction has at least "
                                 f"{sg.ACTIVE_FRAC:g} of its {sg.ACTIVE_PCT:g}th-percentile block RMS (chosen without the test fold's "
                                 f"measurements) gives p < {sg.ALPHA:g} / (number of candidates in the round) "
                                 "(Bonferroni: family-wise error 1 % per round); and the BIC with the "
                                 "autocorrelation-corrected sample size decreases; and the refined model, simulated "
                                 "exactly with the term fitted on one fold, lowers the error on the other fold in each",
                    "ratio_max": sg.RATIO_MAX, "alpha_family": sg.ALPHA, "active_fraction": sg.ACTIVE_FRAC},
           "outside_calibrated_range": outside_doc,
           "base_info": base_info,
           "located": located,
           "calibration": list(map(str, calibration)), "recordings": list(map(str, recordings)),
           "time_s": None}
    doc["time_s"] = round(time.perf_counter() - t_start, 2)
    with open(out / "diagnosis.json", "w") as fh:
        json.dump(_jsonable(doc), fh, indent=1, allow_nan=False)
    if report:
        from .report import write_report
        write_report(out / "report.html", doc, sigs, valid, yr_all, held_pred, png_dir=out / "plots" if png else None)
        doc["time_s"] = round(time.perf_counter() - t_start, 2)
        with open(out / "diagnosis.json", "w") as fh:
            json.dump(_jsonable(doc), fh, indent=1, allow_nan=False)
    return doc


OUT_MARGIN = 0.05   # of the calibrated drive span
OUT_GUARD_S = 0.1   # [s] after the drive comes back into the calibrated range


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
    return dataclasses.replace(s, t=s.t[v], u=s.u[v], y=s.y[v], u2=None if s.u2 is None else s.u2[v],
                               x2=None if s.x2 is None else s.x2[v], temp=None if s.temp is None else s.temp[v],
                               v=s.v[v], h=s.h[v], hyst=s.hyst[v], yb=s.yb[v], ydyn=s.ydyn[v])


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
