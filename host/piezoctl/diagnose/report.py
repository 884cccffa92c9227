"""report.html: the diagnosis in words and plots (self-contained: PNGs embedded as base64).

Plots: residual against time per recording (base and refined), residual spectrum,
residual RMS against drive amplitude, drive rate and other-axis motion, and
measured / base / refined overlays in the window where the first effect acts most.
"""

from __future__ import annotations

import base64
import html
import io
import os

import numpy as np

__all__ = ["write_report"]


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
    return figs


def write_report(path, doc, sigs, valid, yr_all, held_pred=None, png_dir=None) -> None:
    """Write report.html for a diagnosis document and its signals; with ``png_dir``, each figure also as
    ``png_dir/<name>.png`` (residual_time, residual_frequency, residual_amplitude_rate, overlay)."""
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
            parts.append(f"<h3>{html.escape(x['name'])}</h3><p>Parameters: <code>{html.escape(str(x['params']))}"
                         f"</code></p><p>Where: <code>{html.escape(str(x['where']))}</code></p>")
    parts.append("<h2>Where the base model fails</h2><table><tr><th>recording</th><th>NRMSE</th><th>mean [um]"
                 "</th><th>rising / falling mean [um]</th><th>worst windows</th></tr>")
    for r in doc["located"]["per_recording"]:
        wins = "; ".join(f"{w['t0_s']:.2f}-{w['t1_s']:.2f} s ({w['rms_um']:.3f} um)" for w in r["windows"])
        parts.append(f"<tr><td>{html.escape(r['recording'])}</td><td>{r['nrmse']:.4f}</td><td>{r['mean_um']:+.4f}"
                     f"</td><td>{r['mean_rising_um']:+.4f} / {r['mean_falling_um']:+.4f}</td><td>{wins}</td></tr>")
    parts.append("</table>")
    titles = {"residual_time": "Residual against time", "residual_frequency": "Residual spectrum",
              "residual_amplitude_rate": "Residual against drive amplitude, rate and other-axis motion",
              "overlay": "Before / after: measured, base and refined"}
    for k, title in titles.items():
        parts.append(f"<h2>{title}</h2><img src='data:image/png;base64,{figs[k]}'>")
    parts.append("</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(parts))
