"""Cross-coupling benchmark: distributed Hammerstein model vs. modified Preisach baseline.

``tools/bench-coupling`` prints the table (``docs/cross-coupling.md``).

Two-axis data generator (stands in for the C two-axis stage model until it exists)
    Axis 2 (the *other* axis) is driven with :math:`u_2 = 4 + 5\\sin(2\\pi\\varphi(t))` V
    (the paper's excitation) and moves :math:`d_2 = 120 + 120\\,PI[v]` um,
    :math:`v = (u_2 - 4)/5`, with a classical Prandtl-Ishlinskii hysteresis
    :math:`PI[v] = 0.62 v + \\sum_i w_i F_{r_i}[v]` (play operators
    :func:`piezoctl.models.play.play_outputs`, ``r = 0.1, 0.3, 0.5``,
    ``w = 0.20, 0.12, 0.06``), so 0..240 um. The coupled displacement of this axis is

    .. math::

        y = k(x)\\,G_c(s)\\big[e + \\beta e^2/120\\big] + n(t),\\qquad e = d_2 - 120\\ \\mu m,

    with a contact-position gain :math:`k(x) = k_0(1 + 0.5\\hat x - 0.8\\hat x^2 + 0.6\\hat x^3)`,
    :math:`\\hat x = x/240` um (x = column ``x2``, constant per record: the 9 contact
    positions 0, 30, ..., 240 um), :math:`\\beta = 0.3`, coupling dynamics
    :math:`G_c(s) = (1 + s/\\omega_z)^2/(1 + s/\\omega_p)^2`, :math:`f_z = 22.6` Hz,
    :math:`f_p = 1300` Hz (chosen so that the peak-to-peak coupling grows by
    1.19 / 3.39 / 20.4 from 1 Hz to 10 / 35 / 100 Hz; the paper: 1.1 / 3.3 / 21.1),
    :math:`k_0` calibrated so that the mean coupling at 1 Hz is 0.30 % of the drive
    axis' stroke, and white sensor noise :math:`\\sigma = 2` nm. Sample rate 5 kHz.

Protocol (one model of each kind, fitted once)
    Identification: at each of the 9 contact positions, 6000 samples (1.2 s) of a
    linear chirp 1 -> 130 Hz. Validation: sines at 1, 10, 35, 100 Hz, two periods
    (at least 0.2 s), at the 9 training positions and at 8 positions between them
    (15, 45, ..., 225 um); errors over the last period,
    :math:`e = (y - y_{model})/(y_{max} - y_{min})`. "avg" is the mean of
    :math:`|e|` over samples and positions, "worst" the maximum. Coupling is
    :math:`(\\max y - \\min y)/(\\max d_2 - \\min d_2)` in % (noise-free y).
"""

from __future__ import annotations

import argparse
import time
from functools import lru_cache

import numpy as np

from ..ident import hammerstein as ham
from ..ident import preisach
from ..ident.common import Options
from ..ident.tf import simulate_tf
from ..io.recording import Recording
from ..models.play import play_outputs

__all__ = ["FS", "POSITIONS", "generate", "axis2_displacement", "coupled", "run", "main",
           "PAPER", "fit_both", "last_period_errors", "error_row"]

FS = 5000.0                                   # sample rate of the chirp records [Hz]
N_SINE = 6000                                 # samples per sine record (two periods)
POSITIONS = np.linspace(0.0, 240.0, 9)        # contact positions [um]
BETWEEN = 0.5 * (POSITIONS[1:] + POSITIONS[:-1])
FREQS = (1.0, 10.0, 35.0, 100.0)
F_Z, F_P = 22.6, 1300.0                       # coupling zeros / poles [Hz]
BETA = 0.3
NOISE_UM = 0.002

# paper figures: coupling [% of drive], avg-error reduction [%], worst error [%] (Ham., Preisach)
PAPER = {1.0: (0.30, 52, 8.0, 13.0), 10.0: (0.33, 62, None, None),
         35.0: (0.99, 74, None, None), 100.0: (6.34, 55, 2.2, 3.8)}


def axis2_displacement(u2) -> np.ndarray:
    """Hysteretic displacement of the driven axis [um] for its drive u2 [V]."""
    v = (np.asarray(u2, dtype=float) - 4.0) / 5.0
    pi = 0.62 * v + play_outputs(v, [0.1, 0.3, 0.5]) @ np.array([0.20, 0.12, 0.06])
    return 120.0 + 120.0 * pi


def _shape(x) -> np.ndarray:
    xh = np.asarray(x, dtype=float) / 240.0
    return 1.0 + 0.5 * xh - 0.8 * xh ** 2 + 0.6 * xh ** 3


def _dyn(t, e):
    wz, wp = 2 * np.pi * F_Z, 2 * np.pi * F_P
    num = np.polymul([1 / wz, 1.0], [1 / wz, 1.0])
    den = np.polymul([1 / wp, 1.0], [1 / wp, 1.0])
    return simulate_tf(num / den[0], den / den[0], t, e)


def _raw(t, u2, x):
    d2 = axis2_displacement(u2)
    e = d2 - 120.0
    return _shape(x) * _dyn(t, e + BETA * e ** 2 / 120.0), d2


@lru_cache(maxsize=1)
def _k0() -> float:
    """Gain making the mean 1-Hz coupling 0.30 % (last period of a 2-period sine)."""
    ratios = []
    t = np.arange(N_SINE) / (N_SINE / 2.0)
    u2 = 4.0 + 5.0 * np.sin(2 * np.pi * t)
    for x in POSITIONS:
        y, d2 = _raw(t, u2, x)
        last = t >= t[-1] - 1.0
        ratios.append(np.ptp(y[last]) / np.ptp(d2[last]))
    return 0.0030 / float(np.mean(ratios))


def coupled(t, u2, x, noise_seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(coupled displacement y [um], other axis' displacement d2 [um]).

    Parameters
    ----------
    t : ndarray
        Sample times [s] (uniform, 1/FS).
    u2 : ndarray
        Other axis' drive [V].
    x : float
        Contact position [um].
    noise_seed : int or None
        Seed of the sensor noise; None for noise-free output.
    """
    y, d2 = _raw(t, u2, x)
    y = _k0() * y
    if noise_seed is not None:
        y = y + NOISE_UM * np.random.default_rng(noise_seed).standard_normal(y.size)
    return y, d2


def chirp(n: int = 6000, f0: float = 1.0, f1: float = 130.0):
    """(t [s], u2 [V]) of the identification chirp: 4 + 5 sin, linear f0 -> f1 over n samples."""
    t = np.arange(n) / FS
    dur = n / FS
    phase = f0 * t + 0.5 * (f1 - f0) / dur * t ** 2
    return t, 4.0 + 5.0 * np.sin(2 * np.pi * phase)


def sine(f: float, periods: int = 2, min_s: float = 0.2):
    """(t [s], u2 [V]) of a validation sine 4 + 5 sin(2 pi f t)."""
    n = int(round(max(periods / f, min_s) * FS))
    t = np.arange(n) / FS
    return t, 4.0 + 5.0 * np.sin(2 * np.pi * f * t)


def generate(positions=POSITIONS, seed: int = 0) -> list[Recording]:
    """Identification recordings: the chirp at each contact position (columns t, u, y, u2, x2)."""
    recs = []
    for k, x in enumerate(positions):
        t, u2 = chirp()
        y, _ = coupled(t, u2, x, noise_seed=seed * 1000 + k)
        recs.append(Recording(t=t, u=np.zeros_like(t), y=y, u2=u2, x2=np.full(t.size, float(x))))
    return recs


def generate_sines(f: float, positions=POSITIONS, seed: int = 0, n: int = N_SINE) -> list[Recording]:
    """Records of the sine 4 + 5 sin(2 pi f t), two periods in ``n`` samples, per position."""
    fs = n * f / 2.0
    t = np.arange(n) / fs
    u2 = 4.0 + 5.0 * np.sin(2 * np.pi * f * t)
    recs = []
    for k, x in enumerate(positions):
        y, _ = coupled(t, u2, x, noise_seed=seed * 100 + k)
        recs.append(Recording(t=t, u=np.zeros_like(t), y=y, u2=u2, x2=np.full(t.size, float(x))))
    return recs


def _preisach_recs(recs):
    return [Recording(t=r.t, u=r.u2, y=r.y) for r in recs]


def fit_both(recs, opts) -> tuple[dict, dict, float, float]:
    """Fit the distributed Hammerstein model and the modified Preisach baseline (n = 10).

    Parameters
    ----------
    recs : list of Recording
        Coupling records: ``t`` [s], ``u`` [V] (unused), ``y`` [um], ``u2`` [V],
        ``x2`` [um]. The Preisach baseline sees ``u2`` as its drive.
    opts : Options
        Hammerstein options (``hammerstein_*``).

    Returns
    -------
    hp, pp : dict
        Hammerstein and Preisach parameters.
    t_ham, t_pre : float
        Their fit times [s].
    """
    t0 = time.perf_counter()
    hp = ham.fit(recs, opts)
    t_ham = time.perf_counter() - t0
    t0 = time.perf_counter()
    pp = preisach.fit(_preisach_recs(recs), Options(preisach_n=10, offset="shared",
                                                     max_fit_rows=200_000, u_range=None))
    t_pre = time.perf_counter() - t0
    return hp, pp, t_ham, t_pre


def last_period_errors(hp: dict, pp: dict, r: Recording, f: float):
    """Both models' errors on a record over its last period, relative to y's span there.

    Parameters
    ----------
    hp, pp : dict
        Hammerstein and Preisach parameters (:func:`fit_both`).
    r : Recording
        Record of a sine at ``f`` (columns as in :func:`fit_both`).
    f : float
        Its frequency [Hz].

    Returns
    -------
    last : ndarray of bool
        The samples of the last period (``t >= t[-1] - 1/f``).
    e_ham, e_pre : ndarray
        ``|y - y_model| / (max y - min y)`` over those samples [1].
    """
    last = r.t >= r.t[-1] - 1.0 / f
    span = np.ptp(r.y[last])
    yh = ham.simulate(hp, r.t, r.u, r.u2, x2=r.x2)
    yp = preisach.simulate(pp, r.t, r.u2)
    return last, np.abs(r.y - yh)[last] / span, np.abs(r.y - yp)[last] / span


def error_row(eh: list, ep: list, cp: list) -> dict:
    """One table cell group from the per-record errors and couplings.

    Parameters
    ----------
    eh, ep : list of ndarray
        Hammerstein and Preisach relative errors per record [1]
        (:func:`last_period_errors`).
    cp : list of float
        Coupling per record [% of the other axis' displacement].

    Returns
    -------
    dict
        ``coupling`` (mean) [%]; ``ham_avg``, ``ham_worst``, ``pre_avg``,
        ``pre_worst`` (mean and maximum over all samples) [%]; ``reduction``
        of the mean error by Hammerstein against Preisach [%].
    """
    eh, ep = np.concatenate(eh), np.concatenate(ep)
    return {"coupling": float(np.mean(cp)), "ham_avg": 100 * float(eh.mean()),
            "ham_worst": 100 * float(eh.max()), "pre_avg": 100 * float(ep.mean()),
            "pre_worst": 100 * float(ep.max()),
            "reduction": 100 * (1 - float(eh.mean()) / float(ep.mean()))}


def run(settings: dict | None = None, seed: int = 0, verbose: bool = True,
        freqs=FREQS) -> dict:
    """Per frequency: fit both models on the training sines, evaluate on fresh records.

    Returns
    -------
    dict
        ``rows``: per frequency, for the training and the between positions:
        coupling %, Hammerstein avg/worst %, Preisach avg/worst %, reduction %;
        ``fit_s``: total fit times [s]; ``params``: the last Hammerstein parameters.
    """
    opts = Options({f"hammerstein_{k}": v for k, v in (settings or {}).items()})
    rows = []
    t_h = t_p = 0.0
    hp = None
    for f in freqs:
        recs = generate_sines(f, POSITIONS, seed * 1000 + 1)
        hp, pp, dt_h, dt_p = fit_both(recs, opts)
        t_h += dt_h
        t_p += dt_p
        row = {"f": f}
        for label, pos in (("train", POSITIONS), ("between", BETWEEN)):
            eh, ep, cp = [], [], []
            for r in generate_sines(f, pos, seed * 1000 + 2 + (label == "between")):
                last, e_h, e_p = last_period_errors(hp, pp, r, f)
                eh.append(e_h)
                ep.append(e_p)
                # coupling of the noise-free displacement
                y0, d2 = coupled(r.t, r.u2, r.x2[0])
                cp.append(100 * np.ptp(y0[last]) / np.ptp(d2[last]))
            row[label] = error_row(eh, ep, cp)
        rows.append(row)
    out = {"rows": rows, "fit_s": {"hammerstein": t_h, "preisach": t_p}, "params": hp}
    if verbose:
        print(markdown(out))
    return out


def markdown(res: dict) -> str:
    """The comparison table (Markdown) with the paper's figures alongside."""
    lines = ["| f [Hz] | positions | coupling [%] (paper) | Hammerstein avg / worst [%] "
             "| Preisach avg / worst [%] | avg error cut [%] (paper) | worst H / P, paper [%] |",
             "|---:|---|---:|---:|---:|---:|---|"]
    for row in res["rows"]:
        pc, pred, pwh, pwp = PAPER.get(row["f"], ("-", "-", None, None))
        for label in ("train", "between"):
            r = row[label]
            paper_worst = f"{pwh} / {pwp}" if pwh is not None else "-"
            lines.append(
                f"| {row['f']:g} | {label} | {r['coupling']:.2f} ({pc}) | {r['ham_avg']:.2f} / "
                f"{r['ham_worst']:.1f} | {r['pre_avg']:.2f} / {r['pre_worst']:.1f} | "
                f"{r['reduction']:.0f} ({pred}) | {paper_worst} |")
    p = res["params"]
    lines.append("")
    lines.append(f"Hammerstein: m={p['m']}, q={p['q']}, T={p['T']}, degree={p['degree']}, "
                 f"powers={p['powers']}, harmonics={p['harmonics']}, Nc={len(p['channels_fit'])}, "
                 f"refine={p['refine']}, LS rank {p['rank']}; fit {res['fit_s']['hammerstein']:.1f} s. "
                 f"Preisach: n=10; fit {res['fit_s']['preisach']:.1f} s.")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-coupling", description=__doc__.splitlines()[0])
    ap.add_argument("--refine", type=int, default=ham.DEFAULTS["refine"],
                    help="Hammerstein LM refinement iterations (0: the paper's SVD split only)")
    ap.add_argument("--channels", type=int, default=2)
    ap.add_argument("--m", type=int, default=2, help="Laguerre filters")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", choices=("generator", "stage"), default="generator",
                    help="generator: this module's Python generator; stage: the C two-axis stage "
                         "model (piezoctl.bench.coupling_stage; takes --stage and --freqs too)")
    args, rest = ap.parse_known_args(argv)
    if args.data == "stage":
        from .coupling_stage import main as stage_main
        return stage_main([f"--refine={args.refine}", f"--channels={args.channels}", f"--m={args.m}",
                           f"--seed={args.seed}", *rest])
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    run({"refine": args.refine, "channels": args.channels, "m": args.m}, seed=args.seed)
    return 0
