"""report.html: the diagnosis in words and plots (self-contained: PNGs embedded as base64).

Plots: residual against time per recording (base and refined), residual spectrum,
residual RMS against drive amplitude, drive rate and other-axis motion, the residual's
autocorrelation with its 99 % band (whiteness), and measured / base / refined overlays in
the window where the first effect acts most. Tables: effects, each named effect's
parameters and where it acts, the base model's failure per recording, and the drive's
discontinuities.
"""

from __future__ import annotations

import base64
import html
import io
import os

import numpy as np

from .discriminate import inseparable_lines

__all__ = ["write_report", "figures", "whiteness_figure", "where_rows", "discontinuity_rows"]


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _binned(x, e, n=10):
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n + 1)))
    if edges.size < 2:
        return np.array([x.mean()]), np.array([np.sqrt(np.mean(e ** 2))])
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    c = 0.5 * (edges[:-1] + edges[1:])
    r = np.array([np.sqrt(np.mean(e[idx == k] ** 2)) if np.any(idx == k) else np.nan for k in range(c.size)])
    return c, r


def figures(doc, sigs, valid, yr_all) -> dict:
    """The report's figures as base64 PNG strings, by name."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import signal as sig
    figs = {}
    n = len(sigs)
    fig, axs = plt.subplots(n, 1, figsize=(9, 1.8 * n + 0.6), squeeze=False)
    for ax, s, v, yr in zip(axs[:, 0], sigs, valid, yr_all):
        st = max(1, s.t.size // 20000)
        ax.plot(s.t[v][::st], (s.y - s.yb)[v][::st], lw=0.6, label="base")
        ax.plot(s.t[v][::st], (s.y - yr)[v][::st], lw=0.6, label="refined")
        ax.set_ylabel("residual [um]")
        ax.set_title(s.name, fontsize=9)
    axs[0, 0].legend(fontsize=8)
    axs[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    figs["residual_time"] = _png(fig)

    fig, ax = plt.subplots(figsize=(9, 3))
    for lab, ys in (("base", [s.yb for s in sigs]), ("refined", yr_all)):
        ps = []
        for s, v, yh in zip(sigs, valid, ys):
            e = (s.y - yh)[v]
            f, p = sig.welch(e, fs=1.0 / s.dt, nperseg=min(e.size, 8192))
            ps.append(p)
        ax.loglog(f[1:], np.mean([p for p in ps if p.size == ps[0].size], axis=0)[1:], lw=0.8, label=lab)
    ax.set_xlabel("f [Hz]")
    ax.set_ylabel("residual PSD [um^2/Hz]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    figs["residual_frequency"] = _png(fig)

    u = np.concatenate([s.u[v] for s, v in zip(sigs, valid)])
    rate = np.concatenate([np.abs(np.gradient(s.u, s.dt))[v] for s, v in zip(sigs, valid)])
    eb = np.concatenate([(s.y - s.yb)[v] for s, v in zip(sigs, valid)])
    er = np.concatenate([(s.y - yr)[v] for s, v, yr in zip(sigs, valid, yr_all)])
    has2 = any(s.u2 is not None for s in sigs)
    fig, axs = plt.subplots(1, 3 if has2 else 2, figsize=(9, 2.8), squeeze=False)
    for ax, x, lab in ((axs[0, 0], u, "drive u [V]"), (axs[0, 1], rate + 1e-9, "|du/dt| [V/s]")):
        for e, name in ((eb, "base"), (er, "refined")):
            c, r = _binned(x, e)
            ax.plot(c, r, "o-", ms=3, label=name)
        ax.set_xlabel(lab)
        ax.set_ylabel("residual RMS [um]")
    axs[0, 1].set_xscale("log")
    if has2:
        m2 = np.concatenate([np.abs(np.gradient(s.u2, s.dt))[v] if s.u2 is not None else np.zeros(int(v.sum()))
                             for s, v in zip(sigs, valid)])
        for e, name in ((eb, "base"), (er, "refined")):
            c, r = _binned(m2 + 1e-9, e, 6)
            axs[0, 2].plot(c, r, "o-", ms=3, label=name)
        axs[0, 2].set_xlabel("|du2/dt| [V/s]")
        axs[0, 2].set_xscale("log")
    axs[0, 0].legend(fontsize=8)
    fig.tight_layout()
    figs["residual_amplitude_rate"] = _png(fig)

    first = next((x for x in doc["effects"] if x["significant"]), None)
    win = None
    if first and first["where"].get("time_windows"):
        w = max(first["where"]["time_windows"], key=lambda w: w["rms_um"])
        win = (w["recording"], w["t0_s"], w["t1_s"])
    else:
        i = int(np.argmax([np.sqrt(np.mean((s.y - s.yb)[v] ** 2)) for s, v in zip(sigs, valid)]))
        t0 = float(sigs[i].t[valid[i]][0])
        win = (sigs[i].name, t0, t0 + min(2.0, float(sigs[i].t[-1] - t0)))
    i = [s.name for s in sigs].index(win[0])
    s, yr = sigs[i], yr_all[i]
    m = (s.t >= win[1]) & (s.t <= win[2])
    fig, axs = plt.subplots(2, 1, figsize=(9, 4), sharex=True)
    axs[0].plot(s.t[m], s.y[m], "k", lw=0.8, label="measured")
    axs[0].plot(s.t[m], s.yb[m], lw=0.8, label="base")
    axs[0].plot(s.t[m], yr[m], "--", lw=0.8, label="refined")
    axs[0].set_ylabel("y [um]")
    axs[0].legend(fontsize=8)
    axs[1].plot(s.t[m], (s.y - s.yb)[m], lw=0.8, label="base")
    axs[1].plot(s.t[m], (s.y - yr)[m], lw=0.8, label="refined")
    axs[1].set_ylabel("residual [um]")
    axs[1].set_xlabel(f"t [s] ({s.name})")
    fig.tight_layout()
    figs["overlay"] = _png(fig)
    figs["whiteness"] = _png(whiteness_figure(sigs, valid, yr_all))
    return figs


def whiteness_figure(sigs, valid, yr_all):
    """Autocorrelation of the base and refined residuals per recording (decimated to at most 1 kHz, as
    the whiteness test of ``locate.py``), with the 99 % band of a white residual."""
    import matplotlib.pyplot as plt
    from .locate import residual_autocorrelation
    n = len(sigs)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axs = plt.subplots(rows, cols, figsize=(9, 2.6 * rows + 0.4), squeeze=False)
    for ax in axs.flat[n:]:
        ax.set_visible(False)
    for ax, s, v, yr in zip(axs.flat, sigs, valid, yr_all):
        bound = None
        for e, name, mk in (((s.y - s.yb)[v], "base", "o"), ((s.y - yr)[v], "refined", "s")):
            acr = residual_autocorrelation(e, s.dt)
            if acr is None:
                continue
            lag, ac, bound = acr
            ax.plot(lag[1:] * 1e3, ac[1:], mk + "-", ms=2.5, lw=0.7, label=name)
        if bound is not None:
            ax.axhspan(-bound, bound, color="0.85", zorder=0, label="99 % band (white)")
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_title(s.name, fontsize=9)
        ax.set_xlabel("lag [ms]")
        ax.set_ylabel("autocorrelation")
    axs[0, 0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x) for x in v)
    if isinstance(v, dict):
        return "; ".join(f"{k} {_fmt(x)}" for k, x in v.items())
    return str(v)


def _table(head, rows) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    return ("<table><tr>" + th + "</tr>" + "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r)
                                                   + "</tr>" for r in rows) + "</table>")


def where_rows(where: dict) -> list[list[str]]:
    """``where`` of an effect (diagnosis.json) as (aspect, value) rows, units in the aspect."""
    rows = []
    if where.get("recordings"):
        rows.append(["recordings (share of the term's energy)",
                     ", ".join(f"{r['recording']} {100 * r['share']:.0f} %" for r in where["recordings"])])
    for w in where.get("time_windows", []):
        rows.append([f"time window [s] in {w.get('recording', '')}",
                     f"{w['t0_s']:.2f} - {w['t1_s']:.2f} ({w['rms_um'] * 1e3:.1f} nm RMS, "
                     f"{w['x_median']:.1f} x the median window)"])
    if where.get("frequency_bands"):
        rows.append(["frequency bands [Hz] (share of the term's power)",
                     ", ".join(f"{b['f_lo_hz']:g} - {b['f_hi_hz']:g}: {100 * b['share']:.0f} %"
                               for b in where["frequency_bands"])])
    if where.get("amplitude_v"):
        rows.append(["drive where it acts most [V]", f"{where['amplitude_v'][0]:.1f} - {where['amplitude_v'][1]:.1f}"])
    if where.get("rate_v_per_s"):
        rows.append(["drive rate where it acts most [V/s]",
                     f"{where['rate_v_per_s'][0]:.3g} - {where['rate_v_per_s'][1]:.3g}"])
    o = where.get("outside_calibrated_range")
    if o:
        rows.append(["outside the calibrated drive range",
                     f"{100 * o['fraction_of_samples']:.1f} % of the samples (calibrated "
                     f"{o['calibrated_drive_v'][0]:.1f} - {o['calibrated_drive_v'][1]:.1f} V)"])
    for k, v in where.items():
        if k not in ("recordings", "time_windows", "frequency_bands", "amplitude_v", "rate_v_per_s",
                     "outside_calibrated_range"):
            rows.append([k, _fmt(v)])
    return rows


def discontinuity_rows(dd: list) -> list[list[str]]:
    """diagnosis.json's ``drive_discontinuities`` as table rows (file, role, count, jumps)."""
    rows = []
    for f in dd:
        for j in f["jumps"]:
            rows.append([os.path.basename(f["file"]), f["role"], str(f["count"]), str(j["sample"]),
                         f"{j['t_s']:.4f}", f"{j['u_before_v']:.2f} -> {j['u_after_v']:.2f}", f"{j['jump_v']:+.2f}",
                         j["where"]])
    return rows


def write_report(path, doc, sigs, valid, yr_all, held_pred=None, png_dir=None) -> None:
    """Write report.html for a diagnosis document and its signals; with ``png_dir``, each figure also as
    ``png_dir/<name>.png`` (residual_time, residual_frequency, residual_amplitude_rate, whiteness, overlay)."""
    figs = figures(doc, sigs, valid, yr_all)
    if png_dir is not None:
        os.makedirs(png_dir, exist_ok=True)
        for k, b64 in figs.items():
            with open(os.path.join(png_dir, f"{k}.png"), "wb") as fh:
                fh.write(base64.b64decode(b64))
    fit = doc["fit"]
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>piezoctl diagnose</title>",
             "<style>body{font-family:sans-serif;max-width:60em;margin:1em auto}td,th{padding:2px 8px;"
             "border-bottom:1px solid #ddd;text-align:left}img{max-width:100%}</style></head><body>",
             "<h1>Mismatch diagnosis</h1>",
             f"<p><b>Named:</b> {html.escape(', '.join(doc['named']))}</p>",
             *[f"<p><b>Cannot tell apart:</b> {html.escape(line)}</p>" for line in inseparable_lines(doc)],
             f"<p>NRMSE on the recordings: base {fit['base']['nrmse']:.4f}, refined {fit['refined']['nrmse']:.4f}; "
             f"held-out (terms fitted on the other time blocks): base {fit['heldout']['base_nrmse']:.4f}, refined "
             f"{fit['heldout']['refined_nrmse']:.4f}.</p>",
             f"<p><b>Test.</b> {html.escape(doc['test']['statement'])}.</p>",
             "<h2>Effects</h2><table><tr><th>effect</th><th>significant</th><th>held-out NRMSE before &rarr; after"
             "</th><th>evidence</th></tr>"]
    for x in doc["effects"]:
        imp = x["improvement"]
        parts.append(f"<tr><td>{html.escape(x['name'])}</td><td>{'yes' if x['significant'] else 'no'}</td>"
                     f"<td>{imp['nrmse_before']:.4f} &rarr; {imp['nrmse_after']:.4f}</td>"
                     f"<td>{html.escape(x['evidence'])}</td></tr>")
    parts.append("</table>")
    for x in doc["effects"]:
        if x["significant"]:
            parts.append(f"<h3>{html.escape(x['name'])}</h3>")
            parts.append(_table(["parameter (unit in the name)", "value"], [[k, _fmt(v)] for k, v in x["params"].items()]))
            parts.append("<p>Where it acts:</p>" + _table(["aspect", "where"], where_rows(x["where"])))
        elif x["name"] == "none" and x.get("where"):
            parts.append("<h3>none</h3>" + _table(["aspect", "where"], where_rows(x["where"])))
    parts.append("<h2>Where the base model fails</h2><table><tr><th>recording</th><th>NRMSE</th><th>mean [um]"
                 "</th><th>rising / falling mean [um]</th><th>worst windows</th></tr>")
    for r in doc["located"]["per_recording"]:
        wins = "; ".join(f"{w['t0_s']:.2f}-{w['t1_s']:.2f} s ({w['rms_um']:.3f} um)" for w in r["windows"])
        parts.append(f"<tr><td>{html.escape(r['recording'])}</td><td>{r['nrmse']:.4f}</td><td>{r['mean_um']:+.4f}"
                     f"</td><td>{r['mean_rising_um']:+.4f} / {r['mean_falling_um']:+.4f}</td><td>{wins}</td></tr>")
    parts.append("</table>")
    dd = doc.get("drive_discontinuities") or []
    parts.append("<h2>Discontinuities in the drive</h2>")
    if dd:
        from .locate import JUMP_FACTOR, JUMP_NEIGHBOURS, JUMP_SPAN_FRACTION, JUMPS_LISTED
        parts.append(f"<p>Samples where the drive jumps by at least {JUMP_FACTOR:g} times the largest change among "
                     f"the {JUMP_NEIGHBOURS} samples on either side and by at least {100 * JUMP_SPAN_FRACTION:g} % of "
                     "the recording's drive span (docs/diagnose.md). A jump at "
                     "the last sample is usually the recorder resetting the drive, which the stage never followed; "
                     "inside a recording it is a step or a chattering drive. They are flagged, not removed: the "
                     f"models see them as they are. Per file the {JUMPS_LISTED} largest are listed.</p>")
        parts.append(_table(["file", "role", "jumps in the file", "sample", "t [s]", "drive [V]", "jump [V]", "where"],
                            discontinuity_rows(dd)))
    else:
        parts.append("<p>None: no sample-to-sample change of the drive stands out from its neighbours.</p>")
    titles = {"residual_time": ("Residual against time", ""),
              "residual_frequency": ("Residual spectrum", ""),
              "residual_amplitude_rate": ("Residual against drive amplitude, rate and other-axis motion", ""),
              "whiteness": ("Whiteness: autocorrelation of the residual",
                            "Residual (measured - simulated) decimated to at most 1 kHz, autocorrelation at lags "
                            "1-25 samples. A white residual (noise only) stays inside the grey 99 % band; points "
                            "outside mean structure the model has not captured (diagnosis.json: "
                            "located.tests.whiteness_outside_99 is the fraction outside, for the base model)."),
              "overlay": ("Before / after: measured, base and refined", "")}
    for k, (title, note) in titles.items():
        parts.append(f"<h2>{title}</h2>" + (f"<p>{html.escape(note)}</p>" if note else "")
                     + f"<img src='data:image/png;base64,{figs[k]}'>")
    parts.append("</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(parts))
