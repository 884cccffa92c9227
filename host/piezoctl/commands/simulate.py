"""``piezoctl simulate``: run an identified model on a drive signal.

``--model MODEL.json`` runs the model file's kind (``piezoctl.ident``) on the
input recording's ``t``, ``u`` (and ``u2`` when present) and writes a CSV with
header ``t,y``, one row per input row. ``--stage PARAMS.json`` runs the C stage
model (SIL, :mod:`piezoctl.sil.stage`) instead, the same code the SIL build
runs; for a two-axis stage it writes the first axis (``piezoctl stage
simulate`` writes both). The two options are mutually exclusive.

The input needs ``t`` and ``u`` only (``y`` is not read; ``u2`` and ``x2`` are
used when present). Before running, the model's working size (samples x
values per sample, :func:`piezoctl.io.modelcheck.work_columns`) is bounded by
:data:`MAX_WORK_VALUES`; after, an output that is not finite everywhere is
refused (naming the first row) and nothing is written.
"""

from __future__ import annotations

import inspect
import sys

import numpy as np

from ..errors import CliError
from ..ident import get_kind
from ..io.modelcheck import work_columns
from ..io.modelfile import load_model
from ..io.recording import describe_dropped, load_recording, write_csv

__all__ = ["add_parser", "run", "simulate_model", "STAGE_SIMULATOR", "MAX_WORK_VALUES"]

# At most this many float64 values held by a model's simulation (samples x values
# per sample): 2.5e8 values, 2 GB.
MAX_WORK_VALUES = 250_000_000


def _simulate_stage(params_path, t, u, u2):
    """The C stage model (piezoctl.sil.stage): this axis' measured displacement [um]."""
    from ..sil.stage import simulate_stage
    y = simulate_stage(params_path, t, u, u2)
    return y[0] if isinstance(y, tuple) else y


# The stage simulator: a callable (params_path, t, u, u2) -> y [um]. For a
# two-axis stage the first axis is written; `piezoctl stage simulate` gives both.
STAGE_SIMULATOR = _simulate_stage


def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="run a model on a recording's drive and write t,y",
                       description="Run an identified model (MODEL.json) on the drive of a "
                                   "recording and write its predicted displacement as CSV t,y.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", metavar="MODEL.json", help="model file written by piezoctl identify")
    src.add_argument("--stage", metavar="PARAMS.json", help="stage parameters for the C stage model (SIL)")
    p.add_argument("--input", required=True, metavar="X.csv", help="recording whose t, u (and u2) drive the model "
                                                                   "(columns t,u are enough; y is not read)")
    p.add_argument("--drop-outliers", action="store_true",
                   help="drop rows with non-physical values (docs/recordings.md) instead of refusing the input")
    p.add_argument("--out", required=True, metavar="P.csv", help="output CSV, header t,y")
    p.set_defaults(func=run)


def simulate_model(model, t, u, u2=None, x2=None) -> np.ndarray:
    """Output y [um] of a loaded model for drive u [V] at times t [s].

    ``x2`` (the other axis' position [um], column x2) is passed to kinds whose
    ``simulate`` takes it (hammerstein) and is not delayed.

    Applies the model's ``input_delay_s`` (written by ``identify --delay-s``):
    the kind sees ``u`` delayed by that many samples, ``u(0)`` held before.
    """
    mod = get_kind(model.kind)
    t = np.asarray(t, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    delay = float(model.params.get("input_delay_s", 0.0) or 0.0)
    if delay > 0 and t.size > 1:
        d = int(round(delay / float(np.median(np.diff(t)))))
        if d > 0:
            d = min(d, u.size)
            u = np.concatenate([np.full(d, u[0]), u[:u.size - d]])
            if u2 is not None:
                u2 = np.asarray(u2, dtype=np.float64)
                u2 = np.concatenate([np.full(d, u2[0]), u2[:u2.size - d]])
    try:
        kw = {"x2": np.asarray(x2, dtype=np.float64)} \
            if x2 is not None and "x2" in inspect.signature(mod.simulate).parameters else {}
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # checked by check_finite
            y = np.asarray(mod.simulate(model.params, t, u, u2, **kw), dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, CliError):
            raise
        raise CliError(f"{model.path}: parameters do not fit kind {model.kind} "
                       f"({type(exc).__name__}: {exc})") from None
    if y.shape != t.shape:
        raise CliError(f"{model.path}: kind {model.kind} returned {y.shape} outputs for {t.shape} samples")
    return y


def check_work_size(model, samples: int) -> None:
    """Refuse a run whose working size exceeds :data:`MAX_WORK_VALUES` (before allocating)."""
    cols = work_columns(model.kind, model.params)
    if samples * cols > MAX_WORK_VALUES:
        raise CliError(f"{model.path}: kind {model.kind} would hold {samples} samples x {cols} values "
                       f"= {samples * cols * 8 / 2**30:.1f} GiB (limit {MAX_WORK_VALUES * 8 / 2**30:.1f} GiB); "
                       f"simulate a shorter input")


def check_finite(y: np.ndarray, what: str, rec) -> None:
    """Refuse non-finite output, naming the first input row it belongs to."""
    bad = np.nonzero(~np.isfinite(y))[0]
    if bad.size:
        i = int(bad[0])
        raise CliError(f"{what} gives a non-finite output ({y[i]}) at t = {rec.t[i]:.6g} s (sample {i}; "
                       f"{bad.size} such samples) on {rec.path}; nothing written")


def run(args) -> int:
    rec = load_recording(args.input, require=("t", "u"), drop_outliers=getattr(args, "drop_outliers", False))
    if rec.dropped:
        print(describe_dropped(rec), file=sys.stderr)
    if args.stage:
        y = np.asarray(STAGE_SIMULATOR(args.stage, rec.t, rec.u, rec.u2), dtype=np.float64)
        what = f"stage model {args.stage}"
    else:
        model = load_model(args.model)
        if model.kind == "hammerstein" and rec.u2 is None:
            raise CliError(f"{args.input}: a hammerstein model is driven by the other axis: "
                           f"the input needs a column u2")
        check_work_size(model, len(rec))
        y = simulate_model(model, rec.t, rec.u, rec.u2, rec.x2)
        what = f"{model.path} (kind {model.kind})"
    check_finite(y, what, rec)
    write_csv(args.out, {"t": rec.t, "y": y})
    return 0
