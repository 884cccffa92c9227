"""``piezoctl simulate``: run an identified model on a drive signal.

``--model MODEL.json`` runs the model file's kind (``piezoctl.ident``) on the
input recording's ``t``, ``u`` (and ``u2`` when present) and writes a CSV with
header ``t,y``, one row per input row. ``--stage PARAMS.json`` runs the C stage
model (SIL, :mod:`piezoctl.sil.stage`) instead, the same code the SIL build
runs; for a two-axis stage it writes the first axis (``piezoctl stage
simulate`` writes both). The two options are mutually exclusive.
"""

from __future__ import annotations

import inspect

import numpy as np

from ..errors import CliError
from ..ident import get_kind
from ..io.modelfile import load_model
from ..io.recording import load_recording, write_csv

__all__ = ["add_parser", "run", "simulate_model", "STAGE_SIMULATOR"]


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
                                                                   "(y is not needed but the file must be a valid recording)")
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
        y = np.asarray(mod.simulate(model.params, t, u, u2, **kw), dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, CliError):
            raise
        raise CliError(f"{model.path}: parameters do not fit kind {model.kind} "
                       f"({type(exc).__name__}: {exc})") from None
    if y.shape != t.shape:
        raise CliError(f"{model.path}: kind {model.kind} returned {y.shape} outputs for {t.shape} samples")
    return y


def run(args) -> int:
    rec = load_recording(args.input)
    if args.stage:
        y = np.asarray(STAGE_SIMULATOR(args.stage, rec.t, rec.u, rec.u2), dtype=np.float64)
    else:
        model = load_model(args.model)
        y = simulate_model(model, rec.t, rec.u, rec.u2, rec.x2)
    write_csv(args.out, {"t": rec.t, "y": y})
    return 0
