"""``report.html``: one self-contained page (plots inline as PNG)."""

from __future__ import annotations

import base64
import html
import io
import json

import numpy as np

from ..ident import get_kind

__all__ = ["write_report", "figure_html", "append_coupling_html"]


def figure_html(fig) -> str:
    """A matplotlib figure as an inline <img>."""
    buf = io.BytesIO()
    fig.tight_layout()  # subplot titles otherwise overlap the axes above
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    import matplotlib.pyplot as plt
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}">'


def write_report(path, summary: dict, *, forc, model, frf, tf, runs, img: bytes,
                 compensated: str = "feedforward") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ..ident import tf as tfid

    parts = []
    kind = get_kind(model.kind)
    # hysteresis loops, measured and model
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for r in forc:
        yhat = kind.simulate(model.params, r["t"], r["u"])
        ax[0].plot(r["u"], r["y"], lw=0.8, label=f"top {r['top']:.0%}")
        ax[0].plot(r["u"], yhat, "k--", lw=0.6)
        ax[1].plot(r["t"], r["y"] - yhat, lw=0.7)
    ax[0].set(xlabel="drive [V]", ylabel="position [um]", title=f"hysteresis loops (dashed: {model.kind} model)")
    ax[0].legend(fontsize=7)
    ax[1].set(xlabel="time [s]", ylabel="residual [um]", title="model residual per sweep")
    parts.append(("Hysteresis loops and residuals", figure_html(fig)))
    # frequency response and fit
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    w = 2 * np.pi * frf.f_hz
    h = tfid.tf_response(tf.num, tf.den, w) if hasattr(tfid, "tf_response") else np.polyval(tf.num, 1j * w) / np.polyval(tf.den, 1j * w)
    ax[0].loglog(frf.f_hz, frf.mag, ".", ms=2, label="measured (chirp)")
    ax[0].loglog(frf.f_hz, np.abs(h), "r", label="fit")
    ax[1].semilogx(frf.f_hz, frf.phase_deg, ".", ms=2)
    ax[1].semilogx(frf.f_hz, np.degrees(np.unwrap(np.angle(h))), "r")
    ax[0].set(ylabel="|G| [um/V]", title=f"frequency response, resonance {summary['dynamics']['resonance_hz']:.0f} Hz")
    ax[1].set(xlabel="frequency [Hz]", ylabel="phase [deg]")
    ax[0].legend()
    parts.append(("Frequency response and fit", figure_html(fig)))
    # tracking before/after
    keys = [k for k in (1.0, 10.0, 50.0, "multitone")]
    fig, ax = plt.subplots(len(keys), 2, figsize=(11, 2.6 * len(keys)))
    for i, k in enumerate(keys):
        for j, mode in enumerate(("open_loop", compensated)):
            r = runs[(mode, k)]
            ax[i, j].plot(r["t"], r["ref"], "k", lw=0.8, label="reference")
            ax[i, j].plot(r["t"], r["y"], lw=0.8, label="position")
            ax[i, j].plot(r["t"], r["y"] - r["ref"] + r["ref"].mean(), lw=0.6, label="error (offset)")
            name = f"{k:g} Hz triangle" if k != "multitone" else "multitone"
            ax[i, j].set_title(f"{name}, {'uncompensated' if j == 0 else 'compensated'}", fontsize=9)
        ax[i, 0].legend(fontsize=6)
    parts.append(("Tracking before and after", figure_html(fig)))
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{v['rmse_uncompensated_um']:.4f}</td>"
                   f"<td>{v['rmse_compensated_um']:.4f}</td><td>{v['reduction']:.1f}x</td></tr>"
                   for k, v in summary["tracking"].items())
    table = ("<table><tr><th>reference</th><th>RMS error uncompensated [um]</th>"
             f"<th>compensated [um]</th><th>reduction</th></tr>{rows}</table>")
    prov = {"table_crc": summary["table_crc_hex"], "table_kind": summary["table_kind"], "model": model.kind,
            "heldout_nrmse": summary["heldout_nrmse"], "data": model.provenance.get("data"),
            "tool_version": model.provenance.get("tool_version"), "created": model.provenance.get("created"),
            "checks": summary["checks"], "image_bytes": len(img)}
    body = [f"<h1>piezoctl calibration</h1><p>model <b>{model.kind}</b> -> table <b>{summary['table_kind']}</b>, "
            f"crc {summary['table_crc_hex']}, stroke {summary['stroke_um']:.2f} um, "
            f"{summary['duration_s']:.0f} s{', <b>rolled back</b>' if summary['rolled_back'] else ''}.</p>",
            "<h2>Tracking</h2>", table]
    for title, fig_html in parts:
        body += [f"<h2>{html.escape(title)}</h2>", fig_html]
    body += ["<h2>Table provenance</h2>", f"<pre>{html.escape(json.dumps(prov, indent=2, default=str))}</pre>"]
    page = ("<!doctype html><html><head><meta charset='utf-8'><title>piezoctl calibration</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse}"
            "td,th{border:1px solid #aaa;padding:4px 8px;text-align:right}</style></head><body>"
            + "\n".join(body) + "</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(page)


def append_coupling_html(path, coupling: dict) -> None:
    """Add the cross-axis compensation section (two-axis stages) to a written report."""
    rows = []
    for axis, c in sorted(coupling.items()):
        for f, v in c["by_frequency"].items():
            rows.append(f"<tr><td>{html.escape(axis)}</td><td>{c['from_axis']}</td><td>{html.escape(f)} Hz sine</td>"
                        f"<td>{v['rmse_uncompensated_um'] * 1e3:.2f}</td><td>{v['rmse_compensated_um'] * 1e3:.2f}</td>"
                        f"<td>{v['reduction']:.1f}x</td></tr>")
    tables = ", ".join(f"axis {a}: {html.escape(c['table_crc_hex'])}" for a, c in sorted(coupling.items()))
    section = ("<h2>Cross-axis coupling</h2><p>Error of an axis holding mid stroke while the other axis "
               "tracks a sine over 60 % of its stroke, with the cross-coupling compensation bypassed and "
               f"applied (coupling tables {tables}).</p><table><tr><th>axis</th><th>from axis</th>"
               "<th>other axis</th><th>RMS error uncompensated [nm]</th><th>compensated [nm]</th>"
               "<th>reduction</th></tr>" + "".join(rows) + "</table>")
    with open(path, encoding="utf-8") as fh:
        page = fh.read()
    page = page.replace("</body></html>", section + "</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(page)
