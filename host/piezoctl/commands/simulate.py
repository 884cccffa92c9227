"""``piezoctl simulate``: run an identified model on a drive signal, and score it.

``--model MODEL.json`` runs the model file's kind (``piezoctl.ident``) on the
input recording's ``t``, ``u`` (and ``u2`` when present) and writes a CSV with
header ``t,y``, one row per input row. ``--stage PARAMS.json`` runs the C stage
model (SIL, :mod:`piezoctl.sil.stage`) instead, the same code the SIL build
runs; for a two-axis stage it writes the first axis (``piezoctl stage
simulate`` writes both). The two options are mutually exclusive.

The input needs ``t`` and ``u`` only (``u2`` and ``x2`` are used when present).
When it has ``y``, the output is scored against it (:func:`score`: ``nrmse``,
``fit_percent``, ``rmse_um``, ``max_abs_um``; in the text and with ``--json``)
and ``--plot FILE.png`` draws measured and simulated with the error in nm.
Before running, the model's working size (samples x values per sample,
:func:`piezoctl.io.modelcheck.work_columns`) is bounded by
:data:`MAX_WORK_VALUES`; after, an output that is not finite everywhere is
refused (naming the first row) and nothing is written.

``--stage`` runs at one sample rate: ``t`` must be a uniform grid to within 1 %
of a period (:func:`piezoctl.ident.frf.sample_rate`; printed timestamps such as
the valve's and the actuator's pass); the stage then runs on that grid, and a
time column with a gap or a changed rate is refused in one line naming the sample.

numpy, the models and the recording reader are imported when the command runs
(``piezoctl --help`` stays fast); ``load_recording``, ``describe_dropped`` and
``write_csv`` are still attributes of this module (:func:`__getattr__`).
"""

from __future__ import annotations

import inspect
import math
import sys

from ..errors import CliError
from ._options import Progress, add_output, emit
from ._outputs import Outputs, check_output_paths

__all__ = ["add_parser", "run", "simulate_model", "score", "STAGE_SIMULATOR", "MAX_WORK_VALUES"]

# At most this many float64 values held by a model's simulation (samples x values
# per sample): 2.5e8 values, 2 GB.
MAX_WORK_VALUES = 250_000_000

_RECORDING_HELPERS = ("load_recording", "describe_dropped", "write_csv")


def _bind_recording_helpers() -> None:
    """Bind the recording reader/writer (numpy) on first use; a name already set (a test's patch) is kept."""
    from ..io import recording
    for name in _RECORDING_HELPERS:
        globals().setdefault(name, getattr(recording, name))


def __getattr__(name):  # PEP 562: ``simulate.load_recording`` imports on first access
    if name in _RECORDING_HELPERS:
        _bind_recording_helpers()
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _simulate_stage(params_path, t, u, u2):
    """The C stage model (piezoctl.sil.stage): this axis' measured displacement [um]."""
    from ..sil.stage import simulate_stage
    try:
        y = simulate_stage(params_path, t, u, u2)
    except ValueError as exc:
        if isinstance(exc, CliError):
            raise
        raise CliError(f"{params_path}: {exc}") from None
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
    src.add_argument("--stage", metavar="PARAMS.json", help="stage parameters for the C stage model (SIL); "
                                                            "t must be uniform to 1 %% of a period")
    p.add_argument("--input", required=True, metavar="X.csv",
                   help="recording whose t, u (and u2) drive the model (columns t,u are enough; "
                        "with y the output is scored: nrmse, fit_percent, rmse_um, max_abs_um)")
    p.add_argument("--drop-outliers", action="store_true",
                   help="drop rows with non-physical values (docs/recordings.md) instead of refusing the input")
    p.add_argument("--out", required=True, metavar="P.csv", help="output CSV, header t,y")
    p.add_argument("--plot", metavar="FILE.png",
                   help="draw measured (when the input has y) and simulated, and the error in nm")
    add_output(p)
    p.set_defaults(func=run)


def score(y, y_sim) -> dict:
    """How well a simulation ``y_sim`` reproduces the measured ``y`` (both [um]).

    With the error ``e = y - y_sim`` over all N samples:

    - ``rmse_um = sqrt(sum e^2 / N)`` [um];
    - ``max_abs_um = max |e|`` [um];
    - ``nrmse = rmse_um / (max y - min y)`` [1], the project's NRMSE (the one
      ``identify`` and ``diagnose`` report, :func:`piezoctl.ident.common.nrmse`);
    - ``fit_percent = 100 (1 - ||e|| / ||y - mean(y)||)`` [%], MATLAB's ``compare``
      fit (100: exact; 0: no better than the mean; negative: worse).

    A constant ``y`` makes ``nrmse`` and ``fit_percent`` undefined: None.

    Parameters
    ----------
    y, y_sim : array_like, shape (N,)

    Returns
    -------
    dict
        ``nrmse``, ``fit_percent``, ``rmse_um``, ``max_abs_um``.
    """
    import numpy as np

    from ..ident.common import nrmse, rmse

    y = np.asarray(y, dtype=np.float64)
    y_sim = np.asarray(y_sim, dtype=np.float64)
    e = y - y_sim
    spread = float(np.linalg.norm(y - y.mean()))
    nr = nrmse(y, y_sim)
    return {"nrmse": nr if math.isfinite(nr) else None,
            "fit_percent": 100.0 * (1.0 - float(np.linalg.norm(e)) / spread) if spread > 0 else None,
            "rmse_um": rmse(y, y_sim),
            "max_abs_um": float(np.max(np.abs(e)))}


def simulate_model(model, t, u, u2=None, x2=None) -> np.ndarray:
    """Output y [um] of a loaded model for drive u [V] at times t [s].

    ``x2`` (the other axis' position [um], column x2) is passed to kinds whose
    ``simulate`` takes it (hammerstein) and is not delayed.

    Applies the model's ``input_delay_s`` (written by ``identify --delay-s``):
    the kind sees ``u`` delayed by that many samples, ``u(0)`` held before.
    """
    import numpy as np

    from ..ident import get_kind

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
    from ..io.modelcheck import work_columns

    cols = work_columns(model.kind, model.params)
    if samples * cols > MAX_WORK_VALUES:
        raise CliError(f"{model.path}: kind {model.kind} would hold {samples} samples x {cols} values "
                       f"= {samples * cols * 8 / 2**30:.1f} GiB (limit {MAX_WORK_VALUES * 8 / 2**30:.1f} GiB); "
                       f"simulate a shorter input")


def check_finite(y: np.ndarray, what: str, rec) -> None:
    """Refuse non-finite output, naming the first input row it belongs to."""
    import numpy as np

    bad = np.nonzero(~np.isfinite(y))[0]
    if bad.size:
        i = int(bad[0])
        raise CliError(f"{what} gives a non-finite output ({y[i]}) at t = {rec.t[i]:.6g} s (sample {i}; "
                       f"{bad.size} such samples) on {rec.path}; nothing written")


def run(args) -> int:
    import numpy as np

    _bind_recording_helpers()
    check_output_paths(args.out, args.plot)
    rec = load_recording(args.input, require=("t", "u"), drop_outliers=getattr(args, "drop_outliers", False))
    if rec.dropped:
        print(describe_dropped(rec), file=sys.stderr)
    if args.stage:
        from ..ident.frf import sample_rate
        try:
            fs = sample_rate(rec.t)
        except ValueError as exc:
            raise CliError(f"{args.input}: {exc} (the stage model runs at one rate)") from None
        # the stage runs on the uniform grid the timestamps were printed from
        t_grid = rec.t[0] + np.arange(len(rec)) / fs
        with Progress(args, "stage model"):
            y = np.asarray(STAGE_SIMULATOR(args.stage, t_grid, rec.u, rec.u2), dtype=np.float64)
        what = f"stage model {args.stage}"
    else:
        from ..io.modelfile import load_model
        model = load_model(args.model)
        if model.kind == "hammerstein" and rec.u2 is None:
            raise CliError(f"{args.input}: a hammerstein model is driven by the other axis: "
                           f"the input needs a column u2")
        check_work_size(model, len(rec))
        with Progress(args, f"simulate {model.kind}"):
            y = simulate_model(model, rec.t, rec.u, rec.u2, rec.x2)
        what = f"{model.path} (kind {model.kind})"
    check_finite(y, what, rec)
    with Outputs() as files:
        files.write(args.out, lambda p: write_csv(p, {"t": rec.t, "y": y}))
        if args.plot:
            from ..plots import overlay
            with Progress(args, "plot"):
                files.write(args.plot, lambda p: overlay(p, rec.t, rec.y, y, title=f"{args.input}: {what}"))
    result = {"out": args.out, "samples": len(rec), "plot": args.plot}
    lines = [f"{args.out}: {len(rec)} samples simulated by {what}"]
    if rec.y is not None:
        sc = score(rec.y, y)
        result.update(sc)
        nr = "undefined (y constant)" if sc["nrmse"] is None else f"{sc['nrmse']:.4g}"
        fit = "undefined" if sc["fit_percent"] is None else f"{sc['fit_percent']:.2f} %"
        lines.append(f"against y of {args.input}: nrmse {nr}, fit {fit}, rmse {sc['rmse_um']:.4g} um, "
                     f"max |error| {sc['max_abs_um']:.4g} um")
    emit(args, result, lines)
    return 0
