"""``piezoctl identify``: fit a model kind to recordings, write MODEL.json.

Options. argparse must know every option before it knows ``--model``, so the
parser registers the options of every kind of :data:`piezoctl.ident.MODEL_KINDS`
at once, each kind in its own help group:

- options common to all kinds are registered here once
  (:func:`piezoctl.ident.common.add_common_options` plus ``--delay-s`` and
  ``--skip-s``, which this command applies to the data itself);
- a kind's own options are named ``--<kind>-<name>`` (dest ``<kind>_<name>``),
  so kinds cannot clash. A kind whose module does not import, or whose
  options clash with already registered ones, is reported when chosen (and
  in ``--help``) instead of breaking the CLI.

The kind's ``fit(recordings, options)`` receives the loaded
:class:`~piezoctl.io.recording.Recording` list (after ``--delay-s`` and
``--skip-s``) and an :class:`~piezoctl.ident.common.Options` (a dict with
attribute access) holding the common options and the kind's own options,
with their values; the same dict goes to the model file's provenance.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import sys
import time

import numpy as np

from ..errors import CliError
from ..ident import MODEL_KINDS, get_kind
from ..ident.common import IdentError, Options, add_common_options, nrmse
from ..io.modelfile import make_provenance, save_model
from ..io.recording import Recording, describe_dropped, load_recording

__all__ = ["add_parser", "run", "apply_delay", "skip_start", "identify"]

# Per parser build: kind -> list of its option dests, or the reason it is unavailable.
_KIND_DESTS: dict[str, list[str]] = {}
_KIND_BROKEN: dict[str, str] = {}

COMMAND_OPTION_DESTS = ("u_range", "offset", "max_fit_rows", "delay_s", "skip_s", "drop_outliers")


class _Recorder:
    """Forwards ``add_argument`` to an argument group and records the dests."""

    def __init__(self, group):
        self._group = group
        self.dests: list[str] = []

    def add_argument(self, *args, **kwargs):
        action = self._group.add_argument(*args, **kwargs)
        self.dests.append(action.dest)
        return action

    def __getattr__(self, name):
        return getattr(self._group, name)


def add_parser(sub) -> None:
    p = sub.add_parser(
        "identify", help="fit a hysteresis model to recordings and write MODEL.json",
        description="Fit a model kind to one or more recordings (docs/recordings.md) and write "
                    "a model file (docs/model-file.md). Options of a kind are named --KIND-...; "
                    "see docs/identification.md.")
    p.add_argument("--model", required=True, choices=list(MODEL_KINDS), metavar="KIND",
                   help=f"model kind: {', '.join(MODEL_KINDS)}")
    p.add_argument("--data", required=True, nargs="+", metavar="CSV",
                   help="recordings to fit on (all of them, jointly)")
    p.add_argument("--out", required=True, metavar="MODEL.json", help="model file to write")
    common = p.add_argument_group("options of every kind")
    add_common_options(common)
    common.add_argument("--delay-s", type=float, default=0.0, metavar="S",
                        help="input delay [s]: y(t) is modelled from u(t - S), rounded to samples "
                             "(kept in the model; default 0)")
    common.add_argument("--skip-s", type=float, default=0.0, metavar="S",
                        help="drop the first S seconds of every data file before fitting "
                             "(e.g. a start-up step and its ringing; default 0)")
    common.add_argument("--drop-outliers", action="store_true",
                        help="drop rows with non-physical values (docs/recordings.md) and say where, "
                             "instead of refusing the file")
    _KIND_DESTS.clear()
    _KIND_BROKEN.clear()
    for kind in MODEL_KINDS:
        try:
            mod = get_kind(kind)
        except Exception as exc:  # a kind under construction must not break the CLI
            _KIND_BROKEN[kind] = f"module {MODEL_KINDS[kind]} does not import ({type(exc).__name__}: {exc})"
            continue
        group = p.add_argument_group(f"options of --model {kind}", getattr(mod, "DESCRIPTION", None))
        rec = _Recorder(group)
        try:
            mod.add_options(rec)
        except (argparse.ArgumentError, AttributeError, TypeError, ValueError) as exc:
            _KIND_BROKEN[kind] = f"its options cannot be registered ({exc})"
            continue
        _KIND_DESTS[kind] = rec.dests
    if _KIND_BROKEN:
        p.epilog = "unavailable kinds: " + "; ".join(f"{k}: {v}" for k, v in _KIND_BROKEN.items())
    p.set_defaults(func=run)


def apply_delay(rec: Recording, delay_s: float) -> tuple[Recording, int]:
    """Delay the drive by ``delay_s`` [s] (rounded to samples), holding ``u(0)`` before the start.

    Returns the shifted recording and the delay in samples.
    """
    if delay_s < 0:
        raise IdentError(f"--delay-s {delay_s:g}: must be >= 0")
    d = int(round(delay_s / rec.dt)) if delay_s > 0 else 0
    if d == 0:
        return rec, 0
    if d >= len(rec):
        raise IdentError(f"{rec.path}: --delay-s {delay_s:g} is longer than the recording")
    def shift(x):
        return None if x is None else np.concatenate([np.full(d, x[0]), x[:-d]])
    return dataclasses.replace(rec, u=shift(rec.u), u2=shift(rec.u2)), d


def skip_start(rec: Recording, skip_s: float) -> Recording:
    """Drop the samples with ``t < t[0] + skip_s`` [s]."""
    if skip_s < 0:
        raise IdentError(f"--skip-s {skip_s:g}: must be >= 0")
    if skip_s == 0:
        return rec
    k = int(np.searchsorted(rec.t, rec.t[0] + skip_s, side="left"))
    if len(rec) - k < 2:
        raise IdentError(f"{rec.path}: --skip-s {skip_s:g} leaves fewer than 2 samples")
    cut = {name: (None if getattr(rec, name) is None else getattr(rec, name)[k:])
           for name in ("t", "u", "y", "u2", "x2", "reference", "temp")}
    return dataclasses.replace(rec, **cut)


def identify(kind: str, data_paths: list[str], options: Options, out: str | None = None) -> dict:
    """Fit ``kind`` to the recordings and optionally write the model file.

    Returns
    -------
    dict
        ``{"params": ..., "provenance": ...}`` as written.
    """
    if kind in _KIND_BROKEN:
        raise CliError(f"model kind {kind} is not available: {_KIND_BROKEN[kind]}")
    mod = get_kind(kind)
    raw = [load_recording(p, drop_outliers=bool(options.get("drop_outliers", False))) for p in data_paths]
    for r in raw:
        if r.dropped:
            print(describe_dropped(r), file=sys.stderr)
    recs = []
    delay_samples = []
    for r in raw:
        r = skip_start(r, options.get("skip_s", 0.0))
        r, d = apply_delay(r, options.get("delay_s", 0.0))
        recs.append(r)
        delay_samples.append(d)
    t0 = time.perf_counter()
    try:
        params = mod.fit(recs, options)
    except (ValueError, np.linalg.LinAlgError) as exc:
        if isinstance(exc, CliError):
            raise
        raise IdentError(f"fitting {kind} failed: {exc}") from None
    fit_time = time.perf_counter() - t0
    params = dict(params)
    params["input_delay_s"] = float(options.get("delay_s", 0.0))
    scores = []
    scores_off = []
    for r in recs:
        # the other axis' position (column x2) for kinds whose simulate takes it (hammerstein)
        x2 = {"x2": r.x2} if r.x2 is not None and "x2" in inspect.signature(mod.simulate).parameters else {}
        yhat = np.asarray(mod.simulate(params, r.t, r.u, r.u2, **x2), dtype=np.float64)
        scores.append(nrmse(r.y, yhat))
        e = yhat - r.y
        scores_off.append(nrmse(r.y, yhat - e.mean()))
    metrics = {"fit_time_s": round(fit_time, 3),
               "nrmse_offset_removed": scores_off,
               "delay_samples": delay_samples,
               "nrmse_definition": "RMS(yhat - y) / (max(y) - min(y)) over each fitted file"}
    prov = make_provenance(data_paths, {k: v for k, v in options.items()}, nrmse=scores,
                           rows=[len(r) for r in recs], metrics=metrics)
    if out is not None:
        save_model(out, kind, params, prov)
    return {"params": params, "provenance": prov}


def run(args) -> int:
    kind = args.model
    dests = list(COMMAND_OPTION_DESTS) + _KIND_DESTS.get(kind, [])
    options = Options({d: getattr(args, d) for d in dests if hasattr(args, d)})
    if options.get("u_range") is not None:
        options["u_range"] = list(options["u_range"])
    res = identify(kind, args.data, options, out=args.out)
    prov = res["provenance"]
    for entry in prov["data"]:
        print(f"{entry['path']}: NRMSE {entry['nrmse']:.4f} ({entry['rows']} samples)")
    print(f"{kind} model written to {args.out} (fit {prov['metrics']['fit_time_s']:.2f} s)")
    return 0
