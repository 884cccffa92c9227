"""Float-versus-fixed error of every core kernel (``piezoctl golden-error``).

For each kernel on a realistic signal, the float64 reference and the bit-exact
golden model run side by side; the table gives the maximum error in output LSB
(q15) and the SNR in dB (signal power over error power).
"""

from __future__ import annotations

import importlib

import numpy as np

__all__ = ["KERNELS", "error_stats", "rows", "markdown"]

# golden modules that provide error_report() -> list of (case, y_float, y_fixed_q15),
# or a dict with max_lsb and snr_db (xcouple)
KERNELS = ["kp", "rkp", "dcc", "play", "eupi", "eupi_inv", "xcouple"]


def error_stats(y_float: np.ndarray, y_fixed_q15: np.ndarray) -> tuple[float, float]:
    """Maximum error [q15 LSB] and SNR [dB] of a fixed-point output against float.

    Parameters
    ----------
    y_float : ndarray
        Reference output in normalized full-scale units.
    y_fixed_q15 : ndarray of int
        Fixed-point output, q15 integers.
    """
    err = np.asarray(y_fixed_q15, dtype=np.float64) / 32768.0 - np.asarray(y_float, dtype=np.float64)
    max_lsb = float(np.max(np.abs(err)) * 32768.0)
    p_sig = float(np.mean(np.asarray(y_float) ** 2))
    p_err = float(np.mean(err ** 2))
    snr = float("inf") if p_err == 0 else 10.0 * np.log10(p_sig / p_err)
    return max_lsb, snr


def rows() -> list[tuple[str, str, float, float]]:
    """(kernel, case, max error [LSB], SNR [dB]) for every kernel that exists."""
    out = []
    for k in KERNELS:
        try:
            mod = importlib.import_module(f"piezoctl.golden.{k}")
        except ModuleNotFoundError:
            continue
        rep = mod.error_report()
        if isinstance(rep, dict):
            out.append((k, "realistic coupling predictor", rep["max_lsb"], rep["snr_db"]))
            continue
        for case, yf, yq in rep:
            out.append((k, case, *error_stats(yf, yq)))
    return out


def markdown(table: list[tuple[str, str, float, float]]) -> str:
    lines = ["| kernel | signal | max error [LSB q15] | SNR [dB] |", "|---|---|---:|---:|"]
    for k, case, mx, snr in table:
        lines.append(f"| {k} | {case} | {mx:.2f} | {snr:.1f} |")
    return "\n".join(lines) + "\n"
