"""``piezoctl fit-tf``: fit a continuous transfer function to a measured frequency response.

Contract (``docs/dynamics.md``)::

    piezoctl fit-tf --frf FRF.csv --order N --method {wcls,pso-wcls} --out TF.json

``FRF.csv`` has a header line naming the columns ``f_hz,mag,phase_deg`` (order
free, other columns ignored, ``#`` lines skipped); ``f_hz`` [Hz] strictly
increasing and > 0, ``mag`` > 0, every value finite. ``TF.json`` holds ``num``
and ``den`` (descending powers of s, ``den[0] = 1``), ``poles`` as
``[[re, im], ...]`` [rad/s] and ``te`` (mean relative error). Any breach is one
line on stderr and exit status 2.
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np

from ..errors import CliError
from ..ident import tf

FRF_COLUMNS = ("f_hz", "mag", "phase_deg")


def add_parser(sub) -> None:
    p = sub.add_parser("fit-tf", help="fit a transfer function (WCLS / PSO-WCLS) to a frequency response CSV")
    p.add_argument("--frf", required=True, help="CSV with columns f_hz,mag,phase_deg")
    p.add_argument("--order", required=True, type=int, help="denominator order n (>= 1)")
    p.add_argument("--num-order", type=int, default=None, help="numerator order (default: n)")
    p.add_argument("--method", choices=("wcls", "pso-wcls"), default="pso-wcls")
    p.add_argument("--seed", type=int, default=0, help="PSO random seed (default 0)")
    p.add_argument("--te-target", type=float, default=1e-3, help="PSO stop criterion Te* (default 1e-3)")
    p.add_argument("--always-pso", action="store_true", help="run the swarm even if WCLS is stable")
    p.add_argument("--out", required=True, help="output TF.json")
    p.set_defaults(func=run)


def load_frf_csv(path: str) -> tf.FRF:
    """Read an FRF CSV (columns ``f_hz,mag,phase_deg``); raise CliError naming the problem."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as exc:
        raise CliError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not lines:
        raise CliError(f"{path}: empty file (expected header f_hz,mag,phase_deg)")
    rows = list(csv.reader(lines))
    header = [h.strip() for h in rows[0]]
    missing = [c for c in FRF_COLUMNS if c not in header]
    if missing:
        raise CliError(f"{path}: missing column(s) {', '.join(missing)} (header: {','.join(header)})")
    idx = [header.index(c) for c in FRF_COLUMNS]
    data = np.empty((len(rows) - 1, 3))
    for k, row in enumerate(rows[1:]):
        for j, i in enumerate(idx):
            try:
                v = float(row[i])
            except (IndexError, ValueError):
                raise CliError(f"{path}: data row {k + 1}: column {FRF_COLUMNS[j]} is not a number") from None
            if not math.isfinite(v):
                raise CliError(f"{path}: data row {k + 1}: column {FRF_COLUMNS[j]} is {v} (must be finite)")
            data[k, j] = v
    f, mag, ph = data.T
    if f.size < 2:
        raise CliError(f"{path}: need at least 2 frequencies, got {f.size}")
    if np.any(f <= 0):
        raise CliError(f"{path}: f_hz must be > 0 (data row {int(np.argmax(f <= 0)) + 1})")
    bad = np.flatnonzero(np.diff(f) <= 0)
    if bad.size:
        raise CliError(f"{path}: f_hz must increase strictly (data row {int(bad[0]) + 2})")
    if np.any(mag <= 0):
        raise CliError(f"{path}: mag must be > 0 (data row {int(np.argmax(mag <= 0)) + 1})")
    return tf.FRF(f, mag, ph)


def run(args) -> int:
    frf = load_frf_csv(args.frf)
    if args.order < 1:
        raise CliError(f"--order must be >= 1 (got {args.order})")
    if args.num_order is not None and not 0 <= args.num_order <= args.order:
        raise CliError(f"--num-order must be in 0..{args.order} (got {args.num_order})")
    nb = args.order if args.num_order is None else args.num_order
    if 2 * frf.f_hz.size < nb + 1 + args.order:
        raise CliError(f"{args.frf}: {frf.f_hz.size} frequencies cannot determine "
                       f"{nb + 1 + args.order} parameters of an order-{args.order} model")
    opts = {}
    if args.method == "pso-wcls":
        opts = {"seed": args.seed, "te_target": args.te_target, "always": args.always_pso}
    res = tf.fit_tf(frf, args.order, args.method, args.num_order, **opts)
    out = res.to_dict()
    out["order"] = args.order
    out["f_range_hz"] = [float(frf.f_hz[0]), float(frf.f_hz[-1])]
    try:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=2)
            fh.write("\n")
    except OSError as exc:
        raise CliError(f"{args.out}: cannot write: {exc.strerror or exc}") from None
    print(f"fit-tf: {args.method} order {args.order}: te = {res.te:.4g}, "
          f"{'stable' if res.stable else 'UNSTABLE'}, written to {args.out}")
    return 0
