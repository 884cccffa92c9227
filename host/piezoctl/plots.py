"""PNG plots of the command line: Bode plots of a frequency response and its fit, time overlays.

matplotlib (Agg backend, no display) is imported inside each function, so
importing this module costs nothing (``piezoctl --help`` stays fast). Each
function writes one PNG file and returns nothing; a file that cannot be
written raises :class:`~piezoctl.errors.CliError`.
"""

from __future__ import annotations

import os

from .errors import CliError

__all__ = ["bode", "overlay"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path) -> None:
    plt = _pyplot()
    try:
        fig.savefig(os.fspath(path), dpi=110)
    except OSError as exc:
        raise CliError(f"{path}: cannot write the plot: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)


def _resonance_style(r: dict) -> dict:
    """Green solid: supported; orange dotted: flagged (low coherence); red dashed: not supported."""
    if not r.get("supported", True):
        return {"color": "C3", "ls": "--"}
    if r.get("flags"):
        return {"color": "C1", "ls": ":"}
    return {"color": "C2", "ls": "-"}


def bode(path, frf, *, fit=None, gaps=(), resonances=(), title: str = "", units: str = "um/V") -> None:
    """Bode plot (magnitude, phase, coherence) of measured lines and, optionally, a fit.

    Parameters
    ----------
    path : str or path-like
        Output PNG.
    frf : piezoctl.ident.frf.FRF
        The measured lines (markers); its coherence, when present, gets a third axis.
    fit : (num, den), optional
        A continuous transfer function (descending powers of s) drawn as a line
        over the data's range.
    gaps : sequence of Gap
        Bands without data, shaded.
    resonances : sequence of dict
        From :func:`piezoctl.ident.frf.check_resonances`: a vertical line at each
        ``f_hz``: green when supported, orange dotted when flagged (low
        coherence), red dashed when not supported (outside the data, in a gap).
    title : str
    units : str
        Magnitude unit label [output/input].
    """
    import numpy as np

    plt = _pyplot()
    rows = 3 if frf.coherence is not None else 2
    fig, axes = plt.subplots(rows, 1, sharex=True, figsize=(8, 2.4 * rows + 0.6),
                             gridspec_kw={"height_ratios": [3, 2, 1][:rows]})
    ax_m, ax_p = axes[0], axes[1]
    ax_m.loglog(frf.f_hz, frf.mag, ".", ms=4, color="C0", label="measured (H1)")
    ax_p.semilogx(frf.f_hz, frf.phase_deg, ".", ms=4, color="C0")
    if fit is not None:
        from .ident.tf import freqresp
        num, den = fit
        fd = np.logspace(np.log10(frf.f_hz[0]), np.log10(frf.f_hz[-1]), 800)
        hd = freqresp(num, den, 2 * np.pi * fd)
        # unwrap the fit's phase onto the data's branch at the first line
        ph = np.rad2deg(np.unwrap(np.angle(hd)))
        ph += 360.0 * np.round((frf.phase_deg[0] - ph[0]) / 360.0)
        ax_m.loglog(fd, np.abs(hd), "-", color="k", lw=1.2, label="fit")
        ax_p.semilogx(fd, ph, "-", color="k", lw=1.2)
    for ax in axes:
        for g in gaps:
            ax.axvspan(g.lo_hz, g.hi_hz, color="0.85", lw=0, zorder=0)
        for r in resonances:
            ax.axvline(r["f_hz"], lw=0.9, **_resonance_style(r))
        ax.grid(True, which="both", alpha=0.3)
    if gaps:
        ax_m.axvspan(0, 0, color="0.85", label="no data")
    for r in resonances:
        tag = f" ({', '.join(r['flags'])})" if r.get("flags") else ""
        ax_m.plot([], [], label=f"resonance {r['f_hz']:.4g} Hz, zeta {r['damping']:.3g}{tag}",
                  **_resonance_style(r))
    ax_m.set_ylabel(f"magnitude [{units}]")
    ax_p.set_ylabel("phase [deg]")
    ax_m.legend(fontsize=8, loc="best")
    if rows == 3:
        ax_c = axes[2]
        ax_c.semilogx(frf.f_hz, frf.coherence, ".", ms=4, color="C0")
        ax_c.set_ylim(0, 1.05)
        ax_c.set_ylabel("coherence")
    axes[-1].set_xlabel("frequency [Hz]")
    if title:
        ax_m.set_title(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def overlay(path, t, y, y_sim, *, title: str = "") -> None:
    """Measured and simulated displacement over time, and the error ``y - y_sim`` on its own axis in nm.

    Parameters
    ----------
    path : str or path-like
        Output PNG.
    t : array_like
        Time [s].
    y : array_like or None
        Measured displacement [um]; None draws the simulation alone.
    y_sim : array_like
        Simulated displacement [um].
    title : str
    """
    import numpy as np

    plt = _pyplot()
    t = np.asarray(t, dtype=float)
    rows = 1 if y is None else 2
    fig, axes = plt.subplots(rows, 1, sharex=True, figsize=(9, 2.8 * rows + 0.6), squeeze=False)
    ax = axes[0, 0]
    if y is not None:
        ax.plot(t, y, "-", color="C0", lw=1.0, label="measured")
    ax.plot(t, y_sim, "-", color="C1", lw=1.0, label="simulated")
    ax.set_ylabel("displacement [um]")
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, alpha=0.3)
    if y is not None:
        ax_e = axes[1, 0]
        ax_e.plot(t, (np.asarray(y, dtype=float) - np.asarray(y_sim, dtype=float)) * 1e3, "-", color="C3", lw=0.8)
        ax_e.set_ylabel("error y - y_sim [nm]")
        ax_e.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)
