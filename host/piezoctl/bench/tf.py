"""Transfer-function fit benchmark: WCLS, PSO-WCLS and scikit-rf vector fitting.

``tools/bench-tf`` prints the table (``docs/dynamics.md``). Data: the paper's
4th-order actuator model, 200 log-spaced frequencies over 0.01-50 Hz, with
complex multiplicative noise :math:`H(1 + \\sigma(n_1 + j n_2)/\\sqrt2)`,
:math:`n_{1,2} \\sim N(0, 1)`, for each noise level and ``--seeds`` seeds. Each
method fits an order-4 model (numerator order 4). Columns (medians over seeds
except where noted): :math:`T_e` against the noisy data; the largest magnitude
error [dB] and phase error [deg] against the *true* response; the share of
stable fits; the mean fit time. Vector fitting: ``skrf.VectorFitting`` on a
1-port network whose S11 is H, 2 complex pole pairs, constant term, no
proportional term, log-spaced initial poles.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from ..ident import tf

__all__ = ["B_PAPER", "A_PAPER", "run", "main"]

B_PAPER = np.array([0.008933, -1.839, 260.4, 9.313e5, 3.096e7])
A_PAPER = np.array([1.0, 244.2, 3.605e4, 1.898e6, 3.343e7])
F_HZ = np.logspace(-2, np.log10(50.0), 200)


def _vf(f, h):
    import skrf
    from skrf.vectorFitting import VectorFitting

    ntw = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=h.reshape(-1, 1, 1))
    vf = VectorFitting(ntw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vf.vector_fit(n_poles_real=0, n_poles_cmplx=2, init_pole_spacing="log",
                      fit_constant=True, fit_proportional=False)
    return vf.get_model_response(0, 0, f), np.asarray(vf.poles)


def run(levels=(0.01, 0.02, 0.05), seeds: int = 20, verbose: bool = True) -> list[dict]:
    """Run every method on every noisy data set; return one row per (level, method)."""
    w = 2 * np.pi * F_HZ
    h0 = tf.freqresp(B_PAPER, A_PAPER, w)
    methods = ("wcls", "pso-wcls", "pso-wcls always", "vector fitting (skrf)")
    rows = []
    for lev in levels:
        acc = {m: {"te": [], "mag": [], "ph": [], "stable": [], "s": []} for m in methods}
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            h = h0 * (1 + lev * (rng.standard_normal(w.size) + 1j * rng.standard_normal(w.size)) / np.sqrt(2))
            for m in methods:
                t0 = time.perf_counter()
                if m == "wcls":
                    r = tf.wcls(w, h, 4)
                    hm, poles = tf.freqresp(r.num, r.den, w), r.poles
                elif m.startswith("pso"):
                    r = tf.pso_wcls(w, h, 4, seed=seed, always=m.endswith("always"))
                    hm, poles = tf.freqresp(r.num, r.den, w), r.poles
                else:
                    hm, poles = _vf(F_HZ, h)
                a = acc[m]
                a["s"].append(time.perf_counter() - t0)
                a["te"].append(tf.relative_error(hm, h))
                a["mag"].append(float(np.max(np.abs(20 * np.log10(np.abs(hm) / np.abs(h0))))))
                a["ph"].append(float(np.max(np.abs(np.rad2deg(np.angle(hm / h0))))))
                a["stable"].append(bool(np.all(np.real(poles) < 0)))
        for m in methods:
            a = acc[m]
            rows.append({"noise": lev, "method": m, "te": float(np.median(a["te"])),
                         "mag_db": float(np.median(a["mag"])), "phase_deg": float(np.median(a["ph"])),
                         "stable": float(np.mean(a["stable"])), "ms": 1e3 * float(np.mean(a["s"])),
                         "seeds": seeds})
    if verbose:
        print(markdown(rows))
    return rows


def markdown(rows) -> str:
    """The comparison table (Markdown)."""
    lines = ["| noise | method | Te (median) | max mag. error [dB] | max phase error [deg] "
             "| stable | time [ms] |", "|---:|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {100 * r['noise']:g} % | {r['method']} | {r['te']:.4f} | {r['mag_db']:.2f} | "
                     f"{r['phase_deg']:.1f} | {100 * r['stable']:.0f} % | {r['ms']:.1f} |")
    lines.append("")
    lines.append(f"{rows[0]['seeds']} noise seeds per level; errors against the true response over "
                 "0.01-50 Hz (medians).")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-tf", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--levels", type=float, nargs="+", default=[0.01, 0.02, 0.05],
                    help="relative noise levels (default 0.01 0.02 0.05)")
    args = ap.parse_args(argv)
    w = 2 * np.pi * F_HZ
    exact = tf.wcls(w, tf.freqresp(B_PAPER, A_PAPER, w), 4)
    print("Paper model recovered from its own response (WCLS):")
    print("  num =", np.array2string(exact.num, precision=6))
    print("  den =", np.array2string(exact.den, precision=6))
    print("  poles / 100 =", np.array2string(exact.poles / 100, precision=5), f" Te = {exact.te:.2e}")
    print()
    run(tuple(args.levels), args.seeds)
    return 0
