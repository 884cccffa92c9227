"""``report.html``: one self-contained page (plots inline as PNG)."""

from __future__ import annotations

import base64
import html
import io

import numpy as np

from ..ident import get_kind

__all__ = ["write_report", "figure_html", "append_coupling_html", "tracking_figure", "loops_figure",
           "error_frequency_figure", "tone_error_nm"]


def figure_html(fig) -> str:
    """A matplotlib figure as an inline <img>."""
    buf = io.BytesIO()
    if fig.get_layout_engine() is None:
        fig.tight_layout()  # subplot titles otherwise overlap the axes above
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    else:  # laid out already (constrained): a tight bounding box would draw it all a second time
        fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return f'<img src="data:image/png;base64,{base64.b64encode(buf.getvalue()).decode()}">'


NM_PER_UM = 1000.0
KEYS = (1.0, 10.0, 50.0, 100.0, "multitone")   # the acceptance's references, those that ran are plotted


def _keys(runs: dict) -> list:
    return [k for k in KEYS if ("open_loop", k) in runs]
MULTITONE_HZ = (1.0, 7.0, 23.0)   # excitation.multitone_run's default tones


def _ref_name(k) -> str:
    return f"{k:g} Hz triangle" if k != "multitone" else "multitone " + " + ".join(f"{f:g}" for f in MULTITONE_HZ) + " Hz"


def _table(head: list[str], rows: list[list], cls: str = "") -> str:
    """An HTML table; cells are escaped text (already formatted)."""
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table class='{cls}'><tr>{th}</tr>{body}</table>"


def tone_error_nm(run: dict, freqs=MULTITONE_HZ) -> list[float]:
    """Amplitude [nm] of the tracking error (reference - position) at each tone of a multitone run.

    The run holds whole periods of the lowest tone, so each tone falls on a DFT line (the
    nearest line is taken: the capture may be a sample short).
    """
    t, e = np.asarray(run["t"]), np.asarray(run["ref"] - run["y"]) * NM_PER_UM
    n = e.size
    dt = float(np.mean(np.diff(t)))
    spec = np.fft.rfft(e - e.mean())
    f = np.fft.rfftfreq(n, dt)
    return [float(2.0 * np.abs(spec[int(np.argmin(np.abs(f - fk)))]) / n) for fk in freqs]


def tracking_figure(runs: dict, compensated: str):
    """Reference and position [um] above, the error reference - position [nm] on its own axis below,
    for every acceptance reference, uncompensated (left) and compensated (right)."""
    import matplotlib.pyplot as plt
    keys = _keys(runs)
    fig = plt.figure(figsize=(11, 3.4 * len(keys)), layout="constrained")
    for k, sub in zip(keys, fig.subfigures(len(keys), 1)):
        ax = sub.subplots(2, 2, sharex="col", gridspec_kw={"height_ratios": [2, 1]})
        for j, mode in enumerate(("open_loop", compensated)):
            r = runs[(mode, k)]
            a, b = ax[0, j], ax[1, j]
            st = max(1, r["t"].size // 2500)   # the position lines: 2500 points are plenty at this width
            a.plot(r["t"][::st], r["ref"][::st], "k", lw=0.9, label="reference")
            a.plot(r["t"][::st], r["y"][::st], "C0", lw=0.8, label="measured position")
            a.set_ylabel("position [um]")
            a.set_title(f"{_ref_name(k)}, {'uncompensated' if j == 0 else 'compensated'}", fontsize=9)
            a.tick_params(labelbottom=False)
            e = (r["ref"] - r["y"]) * NM_PER_UM
            b.plot(r["t"], e, "C3", lw=0.7)
            b.axhline(0.0, color="0.6", lw=0.5)
            b.set_ylabel("error [nm]")
            b.set_xlabel("time [s]")
            b.set_title(f"error, RMS {np.sqrt(np.mean(e ** 2)):.1f} nm", fontsize=8, loc="right")
        ax[0, 0].legend(fontsize=7, loc="upper right")
    return fig


def loops_figure(runs: dict, compensated: str):
    """Measured position against the reference [um] for each triangle, uncompensated and compensated:
    the hysteresis loop before compensation and what is left of it after."""
    import matplotlib.pyplot as plt
    tri = [k for k in _keys(runs) if k != "multitone"]
    fig, ax = plt.subplots(1, len(tri), figsize=(11, 3.8), squeeze=False)
    for a, k in zip(ax[0], tri):
        lo = min(float(np.min(runs[(m, k)]["ref"])) for m in ("open_loop", compensated))
        hi = max(float(np.max(runs[(m, k)]["ref"])) for m in ("open_loop", compensated))
        a.plot([lo, hi], [lo, hi], color="0.6", lw=0.6, ls=":", label="ideal (position = reference)")
        for mode, colour, name in (("open_loop", "C1", "uncompensated"), (compensated, "C0", "compensated")):
            r = runs[(mode, k)]
            a.plot(r["ref"], r["y"], colour, lw=0.8, label=name)
        a.set(xlabel="reference [um]", ylabel="measured position [um]", title=f"{k:g} Hz triangle")
        a.set_aspect("equal", adjustable="datalim")
    ax[0, 0].legend(fontsize=7, loc="upper left")
    return fig


def error_frequency_figure(summary: dict, runs: dict, compensated: str):
    """Tracking error against frequency: RMS over the triangles [nm], and the multitone's error at each tone."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    tri = [k for k in _keys(runs) if k != "multitone"]
    for key, colour, name in (("rmse_uncompensated_um", "C1", "uncompensated"),
                              ("rmse_compensated_um", "C0", "compensated")):
        ax[0].loglog(tri, [summary["tracking"][f"{k:g}"][key] * NM_PER_UM for k in tri], "o-", color=colour,
                     label=name)
    ax[0].set(xlabel="triangle frequency [Hz]", ylabel="RMS tracking error [nm]",
              title="triangles over 80 % of the stroke")
    for mode, colour, name in (("open_loop", "C1", "uncompensated"), (compensated, "C0", "compensated")):
        ax[1].loglog(MULTITONE_HZ, tone_error_nm(runs[(mode, "multitone")]), "s-", color=colour, label=name)
    ax[1].set(xlabel="tone frequency [Hz]", ylabel="error amplitude at the tone [nm]",
              title="multitone " + " + ".join(f"{f:g}" for f in MULTITONE_HZ) + " Hz")
    for a in ax:
        a.grid(True, which="both", lw=0.3)
        a.legend(fontsize=8)
    return fig


def write_report(path, summary: dict, *, forc, model, frf, tf, runs, img: bytes,
                 compensated: str = "feedforward", steps: list[dict] | None = None, say=None) -> None:
    """Write ``report.html``: summary, tracking table, steps, plots and the table's provenance.

    Parameters
    ----------
    summary : dict
        The calibration summary (``summary.json``'s content).
    forc : list of dict
        The excitation sweeps (``t`` [s], ``u`` [V], ``y`` [um], ``top``).
    model : Model
        The flashed model.
    frf, tf
        The measured frequency response and its second-order fit.
    runs : dict
        Acceptance runs keyed (mode, 1.0 | 10.0 | 50.0 | "multitone"): ``t`` [s], ``ref``, ``y`` [um].
    img : bytes
        The table image.
    steps : list of dict, optional
        ``step``, ``name``, ``seconds``, ``result`` per step (``summary["steps"]``).
    say : callable, optional
        Called with a line of progress before each figure (a few seconds each on a busy machine).
    """
    say = say or (lambda text: None)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ..ident import tf as tfid

    parts = []
    kind = get_kind(model.kind)
    dyn = summary["dynamics"]
    f_res = dyn["resonance_hz"]
    # hysteresis loops, measured and model
    say("figure: excitation sweeps and the model ...")
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for r in forc:
        yhat = kind.simulate(model.params, r["t"], r["u"])
        ax[0].plot(r["u"], r["y"], lw=0.8, label=f"top {r['top']:.0%}")
        ax[0].plot(r["u"], yhat, "k--", lw=0.6)
        ax[1].plot(r["t"], (r["y"] - yhat) * NM_PER_UM, lw=0.7, label=f"top {r['top']:.0%}")
    ax[0].set(xlabel="drive [V]", ylabel="position [um]", title=f"excitation sweeps (dashed: {model.kind} model)")
    ax[0].legend(fontsize=7)
    ax[1].set(xlabel="time [s]", ylabel="measured - model [nm]", title="model residual per sweep")
    ax[1].legend(fontsize=7)
    parts.append(("Identification: hysteresis loops and the model's residual", "", figure_html(fig)))
    # frequency response and fit
    say("figure: frequency response ...")
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    w = 2 * np.pi * frf.f_hz
    h = tfid.freqresp(tf.num, tf.den, w)
    ax[0].loglog(frf.f_hz, frf.mag, ".", ms=2, label="measured (chirp)")
    ax[0].loglog(frf.f_hz, np.abs(h), "r", lw=1, label=f"2nd-order fit (poles at {dyn['fit_natural_hz']:.0f} Hz)")
    ax[1].semilogx(frf.f_hz, frf.phase_deg, ".", ms=2)
    ax[1].semilogx(frf.f_hz, np.degrees(np.unwrap(np.angle(h))), "r", lw=1)
    for a in ax:
        a.axvline(f_res, color="k", ls=":", lw=0.8, label=f"resonance {f_res:.0f} Hz (measured peak)")
        a.grid(True, which="both", lw=0.3)
    ax[0].set(ylabel="|G| [um/V]", title=f"frequency response (drive -> position), resonance {f_res:.0f} Hz")
    ax[1].set(xlabel="frequency [Hz]", ylabel="phase [deg]")
    ax[0].legend(fontsize=8)
    res_note = (f"The resonance, {f_res:.1f} Hz, is the frequency of the largest measured magnitude (the chirp's "
                f"frequency response, lines {np.median(np.diff(frf.f_hz)):.2f} Hz apart); the notch and the input "
                f"shaper are placed there (damping {dyn.get('damping', float('nan')):.3f} from the half-power "
                f"width). The red curve is a second-order fit (PSO-WCLS, relative error {dyn['te']:.2f}); its "
                f"poles are at {dyn['fit_natural_hz']:.1f} Hz: two poles cannot also hold the amplifier's "
                "bandwidth and the tick's delay, so the fit trades the narrow peak for the broad band. The fit "
                "is kept in summary.json (dynamics.num, den) and is not used by the controller.")
    parts.append(("Frequency response and fit", res_note, figure_html(fig)))
    say("figure: tracking ...")
    parts.append(("Tracking before and after compensation",
                  "Reference and measured position; below each, the error reference - position in nm on its "
                  "own axis (the compensated error is up to 200 times smaller, so each panel has its own scale).",
                  figure_html(tracking_figure(runs, compensated))))
    say("figure: hysteresis loops before and after ...")
    parts.append(("Hysteresis loops before and after compensation",
                  "Measured position against the reference: uncompensated, the stage's hysteresis loop; "
                  "compensated, what is left of it.", figure_html(loops_figure(runs, compensated))))
    say("figure: tracking error against frequency ...")
    parts.append(("Tracking error against frequency", "", figure_html(error_frequency_figure(summary, runs,
                                                                                            compensated))))
    track = _table(["reference", "frequency [Hz]", "RMS error uncompensated [nm]", "RMS error compensated [nm]",
                    "reduction"],
                   [[_ref_name(float(k) if k != "multitone" else k),
                     k if k != "multitone" else " + ".join(f"{f:g}" for f in MULTITONE_HZ),
                     f"{v['rmse_uncompensated_um'] * NM_PER_UM:.1f}", f"{v['rmse_compensated_um'] * NM_PER_UM:.1f}",
                     f"{v['reduction']:.1f}x"] for k, v in summary["tracking"].items()])
    part_rows = []
    for k, v in summary["tracking"].items():
        p = v.get("rmse_by_part_um")
        if not p:
            continue
        lr = v.get("learned", {})
        inv = p.get("dynamics_inverse")
        part_rows.append([_ref_name(float(k) if k != "multitone" else k)]
                         + [f"{x * NM_PER_UM:.1f}" for x in (v["rmse_uncompensated_um"], p["feedback"],
                                                             p["hysteresis"], p["dynamics"])]
                         + ["-" if inv is None else f"{inv * NM_PER_UM:.1f}"
                            + (" (worse)" if inv > p["dynamics"] else "")]
                         + [f"{p['learned'] * NM_PER_UM:.1f}", f"{lr.get('trials', 0)} ({lr.get('refused', 0)} refused)"])
    rs = summary.get("random_scan")
    if rs:
        q = rs["rmse_by_part_um"]
        part_rows.append([f"random scan, {len(rs['tones_hz'])} tones {rs['band_hz'][0]:.0f}..{rs['band_hz'][1]:.0f} Hz "
                          "(not known in advance)"]
                         + [f"{q[k] * NM_PER_UM:.1f}" for k in ("uncompensated", "feedback", "hysteresis", "dynamics")]
                         + [f"{q['dynamics_inverse'] * NM_PER_UM:.1f}"
                            + (" (worse)" if q["dynamics_inverse"] > q["dynamics"] else "")]
                         + ["-", "none (nothing to learn from)"])
    parts_table = _table(["reference", "uncompensated [nm]", "feedback only (PI + notch) [nm]",
                          "+ hysteresis inverse [nm]", "+ dynamics: preview and shaper [nm]",
                          "instead: + dynamics inverse (preview, FIR) [nm]",
                          "+ learned feedforward [nm]", "learning trials"], part_rows) if part_rows else ""
    step_table = _table(["step", "what", "time [s]", "result"],
                        [[f"{r['step']}/7", r["name"], "-" if r.get("seconds") is None else f"{r['seconds']:.1f}",
                          r.get("result", "")] for r in (steps or [])], cls="left")
    comp = summary["compensation"]
    comp_table = _table(["setting", "value"], [
        ["mode", comp["mode"]], ["resonance, notch and shaper [Hz]", f"{comp['notch_hz']:.1f}"],
        ["damping", f"{comp['damping']:.4f}"], ["crossover [Hz]", f"{comp['crossover_hz']:.0f}"],
        ["kp", f"{comp['kp']:.4g}"], ["ki per tick", f"{comp['ki_per_tick']:.4g}"],
        ["shaper spacing [ticks]", comp["shaper_ticks"]], ["shaper taps (q15)", ", ".join(map(str, comp["shaper_q15"]))],
        ["preview [ticks]", comp["preview_ticks"]]]
        + ([["dynamics inverse: taps, spacing [ticks]", f"{len(di['taps_q13'])}, {di['spacing_ticks']}"],
            ["dynamics inverse: inverted band [Hz]", f"{di['band_hz'][0]:.0f} .. {di['band_hz'][1]:.0f}"],
            ["dynamics inverse: preview [ticks]", di["preview_ticks"]],
            ["dynamics inverse: max |H|, in-band error (preview and shaper)",
             f"{di['max_gain']:.2f}, {di['inband_error']:.3f} ({di['shaper_inband_error']:.3f})"],
            ["dynamics inverse: taps (q13)", ", ".join(map(str, di["taps_q13"]))]]
           if (di := comp.get("dynamics_inverse")) else []), cls="left")
    checks = summary["checks"]
    prov_rows = [["table CRC", summary["table_crc_hex"]], ["table kind", summary["table_kind"]],
                 ["image size [bytes]", len(img)], ["model", model.kind],
                 ["held-out NRMSE", f"{summary['heldout_nrmse']:.4f}"],
                 ["held-out NRMSE per candidate", ", ".join(f"{k} {v:.4f}" for k, v in
                                                            summary["heldout_nrmse_by_model"].items())],
                 ["tool version", model.provenance.get("tool_version")], ["model created", model.provenance.get("created")],
                 ["forward(inverse) max error [fraction of range]", f"{checks['forward_inverse_max_error_fraction']:.2e}"],
                 ["fixed point vs float inverse [LSB]", f"{checks['quantization_max_lsb']:.2f}"]]
    prov_rows += [[k, f"{v:.4g}" if isinstance(v, float) else v] for k, v in checks.items()
                  if k not in ("forward_inverse_max_error_fraction", "quantization_max_lsb")]
    target = summary.get("target") or {}
    prov_rows += [[f"target {k}", v] for k, v in target.items()]
    data_rows = [[d.get("path"), d.get("rows"), "-" if d.get("nrmse") is None else f"{d['nrmse']:.4f}",
                  d.get("sha256", "")] for d in model.provenance.get("data", [])]
    body = [f"<h1>piezoctl calibration</h1><p>Model <b>{html.escape(model.kind)}</b> &rarr; table "
            f"<b>{html.escape(summary['table_kind'])}</b>, CRC {summary['table_crc_hex']}, stroke "
            f"{summary['stroke_um']:.2f} um, resonance {f_res:.0f} Hz, {summary['duration_s']:.0f} s"
            f"{', <b>rolled back</b>' if summary['rolled_back'] else ''}.</p>",
            "<h2>Tracking</h2><p>RMS of reference minus measured position over whole periods after at least "
            "50 ms of settling; uncompensated: the best straight line, no preview, shaper or feedback; "
            "compensated: the table's inverse, preview, shaper, PI + notch and the learned feedforward "
            "played with the wave.</p>", track,
            "<h3>What each part contributes</h3><p>The same references, each configuration measured on its "
            "own: the feedback loop alone; plus the hysteresis inverse (the table); plus the dynamics "
            "(reference preview of the loop's lag and the input shaper at the resonance); plus the "
            "feedforward learned over trials on the controller (iterative learning control, stored with the "
            "wave and played by the firmware). The dynamics inverse is the alternative to preview and shaper "
            "for any reference: a least-squares FIR on the early reference so that the measured dynamics times "
            "it is a pure delay over the inverted band (Compensation below), measured instead of the shaper; "
            "(worse) marks a reference where it leaves more than preview and shaper. The random scan is a "
            "reference no learning has seen: 8 tones at random frequencies and phases.</p>", parts_table,
            "<h2>Steps</h2>", step_table]
    for title, note, fig_html in parts:
        body += [f"<h2>{html.escape(title)}</h2>"] + ([f"<p>{html.escape(note)}</p>"] if note else []) + [fig_html]
    body += ["<h2>Compensation</h2>", comp_table,
             "<h2>Table provenance</h2>", _table(["item", "value"], prov_rows, cls="left"),
             "<h3>Recordings the model was fitted on</h3>",
             _table(["file", "samples", "fit NRMSE", "sha256"], data_rows, cls="left")]
    page = ("<!doctype html><html><head><meta charset='utf-8'><title>piezoctl calibration</title>"
            "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;"
            "margin:0.5em 0}td,th{border:1px solid #aaa;padding:4px 8px;text-align:right}"
            "table.left td,table.left th{text-align:left}img{max-width:100%}</style></head><body>"
            + "\n".join(body) + "</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(page)


def append_coupling_html(path, coupling: dict) -> None:
    """Add the cross-axis compensation section (two-axis stages) to a written report."""
    rows = []
    for axis, c in sorted(coupling.items()):
        for f, v in c["by_frequency"].items():
            table_only = v.get("rmse_table_only_um")
            rows.append(f"<tr><td>{html.escape(axis)}</td><td>{c['from_axis']}</td><td>{html.escape(f)}</td>"
                        f"<td>{v['rmse_uncompensated_um'] * 1e3:.2f}</td>"
                        f"<td>{'-' if table_only is None else f'{table_only * 1e3:.2f}'}</td>"
                        f"<td>{v['rmse_compensated_um'] * 1e3:.2f}</td><td>{v['reduction']:.1f}x</td></tr>")
    tables = ", ".join(f"axis {a}: {html.escape(c['table_crc_hex'])}" for a, c in sorted(coupling.items()))
    section = ("<h2>Cross-axis coupling</h2><p>Error of an axis holding mid stroke while the other axis "
               "tracks a triangle over 60 % of its stroke: uncompensated (its feedback, the coupling table "
               f"bypassed), with the coupling table (tables {tables}), and with the table plus the held "
               "axis' learned feedforward, started in step with the other axis' wave.</p>"
               "<table><tr><th>axis</th><th>from axis</th><th>other axis triangle [Hz]</th>"
               "<th>RMS error uncompensated [nm]</th><th>coupling table [nm]</th>"
               "<th>+ learned feedforward [nm]</th><th>reduction</th></tr>" + "".join(rows) + "</table>")
    with open(path, encoding="utf-8") as fh:
        page = fh.read()
    page = page.replace("</body></html>", section + "</body></html>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(page)
