"""``piezoctl identify``: fit a model kind to recordings, write MODEL.json.

Options. Options common to all kinds are registered here
(:func:`piezoctl.ident.common.add_common_options` plus ``--delay-s`` and
``--skip-s``, which this command applies to the data itself). A kind's own
options are named ``--<kind>-<name>`` (dest ``<kind>_<name>``), so kinds
cannot clash; only the options of the kind named by ``--model`` are
registered (so ``identify --model kp --help`` lists kp's options and imports
no other kind). An option of another kind is refused with one line naming
the kind(s) that take it (``--model kp --rkp-levels 4``: "an option of
--model rkp"; ``--order 4``: "--model cascade takes --cascade-order"). A
kind whose module does not import, or whose options cannot be registered,
is reported when chosen instead of breaking the CLI.

The kind's ``fit(recordings, options)`` receives the loaded
:class:`~piezoctl.io.recording.Recording` list (after ``--delay-s`` and
``--skip-s``) and an :class:`~piezoctl.ident.common.Options` (a dict with
attribute access) holding the common options and the kind's own options,
with their values; the same dict goes to the model file's provenance.

Output: a line per data file (NRMSE, samples) and one naming the model file,
or with ``--json`` one object ``{"model", "out", "data": [{"path", "nrmse",
"rows"}], "fit_time_s"}``. The fit reports progress on stderr.
numpy and the kind modules are imported when the command runs, not when
the CLI starts.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import sys
import time

from ..errors import CliError
from ..ident import MODEL_KINDS, get_kind
from ._options import Progress, add_output, emit, progress

__all__ = ["add_parser", "run", "apply_delay", "skip_start", "identify", "kind_options"]

# Per parser build: kind -> list of its option dests, or the reason it is unavailable.
_KIND_DESTS: dict[str, list[str]] = {}
_KIND_BROKEN: dict[str, str] = {}

COMMAND_OPTION_DESTS = ("u_range", "offset", "max_fit_rows", "delay_s", "skip_s", "drop_outliers")


class _Recorder:
    """Forwards ``add_argument`` to an argument group and records the dests."""

    def __init__(self, group):
        self._group = group
        self.dests: list[str] = []
        self.flags: list[str] = []

    def add_argument(self, *args, **kwargs):
        action = self._group.add_argument(*args, **kwargs)
        self.dests.append(action.dest)
        self.flags.extend(s for s in action.option_strings if s.startswith("--"))
        return action

    def __getattr__(self, name):
        return getattr(self._group, name)


def add_parser(sub) -> None:
    p = sub.add_parser(
        "identify", help="fit a hysteresis model to recordings and write MODEL.json",
        description="Fit a model kind to one or more recordings (docs/recordings.md) and write "
                    "a model file (docs/model-file.md). Options of a kind are named --KIND-...; "
                    "see docs/identification.md.",
        epilog="the options of a kind: piezoctl identify --model KIND --help")
    p.add_argument("--model", required=True, choices=list(MODEL_KINDS), metavar="KIND",
                   help=f"model kind: {', '.join(MODEL_KINDS)}")
    p.add_argument("--data", required=True, nargs="+", metavar="CSV",
                   help="recordings to fit on (all of them, jointly)")
    p.add_argument("--out", required=True, metavar="MODEL.json", help="model file to write")
    add_output(p, json_help="print the result as one JSON object on stdout: model, out, "
                            "data [{path, nrmse, rows}], fit_time_s")
    common = p.add_argument_group("options of every kind")
    from ..ident.common import add_common_options  # numpy, not scipy
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
    if hasattr(p, "before_parse"):   # piezoctl's CommandParser: the kind's options when it parses
        p.before_parse(_add_kind_options)
    else:                     # a plain argparse parser: every kind's options now
        for kind in MODEL_KINDS:
            _register_kind(p, kind)
    p.set_defaults(func=run)


def _model_in(argv) -> str | None:
    """The value of ``--model`` in an argument list (``--model K`` or ``--model=K``)."""
    argv = list(argv or [])
    for k, a in enumerate(argv):
        if a == "--model" and k + 1 < len(argv):
            return argv[k + 1]
        if a.startswith("--model="):
            return a.split("=", 1)[1]
    return None


def _add_kind_options(p, argv) -> None:
    """Register the options of the kind named by ``--model`` in ``argv`` (none if it names none)."""
    kind = _model_in(argv)
    registered = p.__dict__.setdefault("_piezoctl_kinds", set())   # a parser may parse twice
    if kind in MODEL_KINDS and kind not in registered:
        registered.add(kind)
        _register_kind(p, kind)
    p.explain_unknown = lambda extras: _explain_unknown(extras, kind if kind in MODEL_KINDS else None)


def _register_kind(p, kind: str) -> _Recorder | None:
    try:
        mod = get_kind(kind)
    except Exception as exc:  # a kind under construction must not break the CLI
        _KIND_BROKEN[kind] = f"module {MODEL_KINDS[kind]} does not import ({type(exc).__name__}: {exc})"
        return None
    group = p.add_argument_group(f"options of --model {kind}", getattr(mod, "DESCRIPTION", None))
    rec = _Recorder(group)
    try:
        mod.add_options(rec)
    except (argparse.ArgumentError, AttributeError, TypeError, ValueError) as exc:
        _KIND_BROKEN[kind] = f"its options cannot be registered ({exc})"
        return None
    _KIND_DESTS[kind] = rec.dests
    return rec


def kind_options() -> dict[str, list[str]]:
    """Every kind's own option flags, ``{kind: ["--kp-levels", ...]}`` (imports every kind)."""
    out = {}
    for kind in MODEL_KINDS:
        scratch = argparse.ArgumentParser(add_help=False)
        try:
            get_kind(kind).add_options(rec := _Recorder(scratch))
        except Exception:  # an unavailable kind takes no options; it is reported when chosen
            continue
        out[kind] = rec.flags
    return out


def _explain_unknown(extras: list[str], chosen: str | None) -> str | None:
    """One line for options of another kind, or options no kind takes under that name."""
    flags = [a.split("=", 1)[0] for a in extras if a.startswith("--")]
    if not flags:
        return None
    owners = kind_options()
    parts = []
    for flag in flags:
        of = [k for k, fl in owners.items() if flag in fl]
        if of:
            parts.append(f"{flag} is an option of --model {' / '.join(of)}"
                         + (f", not of --model {chosen}" if chosen else ""))
            continue
        tail = flag[2:]
        like = [(k, f) for k, fl in owners.items() for f in fl if f == f"--{k}-{tail}"] \
            or [(k, f) for k, fl in owners.items() for f in fl if f.endswith("-" + tail)]
        if like:
            parts.append(f"{flag} is not an option of identify; "
                         + "; ".join(f"--model {k} takes {f}" for k, f in like))
    if not parts:
        return None
    return "; ".join(parts)


def apply_delay(rec, delay_s: float):
    """Delay the drive by ``delay_s`` [s] (rounded to samples), holding ``u(0)`` before the start.

    Returns the shifted :class:`~piezoctl.io.recording.Recording` and the delay in samples.
    """
    import numpy as np

    from ..ident.common import IdentError
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


def skip_start(rec, skip_s: float):
    """Drop the samples with ``t < t[0] + skip_s`` [s] of a :class:`~piezoctl.io.recording.Recording`."""
    import numpy as np

    from ..ident.common import IdentError
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


def identify(kind: str, data_paths: list[str], options, out: str | None = None, args=None) -> dict:
    """Fit ``kind`` to the recordings and optionally write the model file.

    ``options`` is an :class:`~piezoctl.ident.common.Options`; ``args`` (the
    command's namespace, optional) decides whether progress goes to stderr.

    Returns
    -------
    dict
        ``{"params": ..., "provenance": ...}`` as written.
    """
    import numpy as np

    from ..ident.common import IdentError, nrmse
    from ..io.modelfile import make_provenance, save_model
    from ..io.recording import describe_dropped, load_recording

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
        with Progress(args, f"fitting {kind} to {sum(len(r) for r in recs)} samples of "
                            f"{len(recs)} file{'s' if len(recs) > 1 else ''}"):
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
    if args is not None:
        progress(args, "scoring the model on the data")
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
    from ..ident.common import Options
    kind = args.model
    dests = list(COMMAND_OPTION_DESTS) + _KIND_DESTS.get(kind, [])
    options = Options({d: getattr(args, d) for d in dests if hasattr(args, d)})
    if options.get("u_range") is not None:
        options["u_range"] = list(options["u_range"])
    res = identify(kind, args.data, options, out=args.out, args=args)
    prov = res["provenance"]
    data = [{"path": e["path"], "nrmse": e["nrmse"], "rows": e["rows"]} for e in prov["data"]]
    fit_s = prov["metrics"]["fit_time_s"]
    lines = [f"{e['path']}: NRMSE {e['nrmse']:.4f} ({e['rows']} samples)" for e in data]
    lines.append(f"{kind} model written to {args.out} (fit {fit_s:.2f} s)")
    emit(args, {"model": kind, "out": args.out, "data": data, "fit_time_s": fit_s}, lines)
    return 0
