"""MODEL.json: an identified model with the provenance of its fit.

Written by ``piezoctl identify``, read by ``piezoctl simulate`` and the table
generators. The format is described in ``docs/model-file.md``::

    {
      "format": "piezoctl-model",
      "version": 1,
      "kind": "kp",
      "params": {...},                      # the kind's parameters, physical units
      "provenance": {
        "tool": "piezoctl", "tool_version": "0.1.0",
        "created": "2025-01-01T12:00:00Z",
        "data": [{"path": "run1.csv", "sha256": "...", "rows": 300000,
                  "nrmse": 0.012}],
        "options": {...},                   # every identify option used
        "metrics": {...}                    # optional: more fit figures
      }
    }
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import math
import os
import re
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from .. import __version__
from ..errors import CliError
from .modelcheck import MAX_DEPTH, ModelFileError, check_params

__all__ = [
    "FORMAT", "VERSION", "Model", "ModelFileError",
    "save_model", "load_model", "file_sha256", "make_provenance", "to_jsonable", "changed_data",
]

FORMAT = "piezoctl-model"
VERSION = 1

MAX_FILE_BYTES = 256 << 20   # a 100-level KP model is about 200 kB

_HEX64 = re.compile(r"^[0-9a-f]{64}$")


@dataclasses.dataclass
class Model:
    """A loaded model file.

    Attributes
    ----------
    kind : str
        Model kind, a key of :data:`piezoctl.ident.MODEL_KINDS`.
    params : dict
        The kind's parameters (physical units: V, um, s).
    provenance : dict
        Data files with their SHA-256, options, tool version, time, metrics.
    version : int
        Format version of the file.
    path : str or None
        File it was read from.
    """

    kind: str
    params: dict
    provenance: dict
    version: int = VERSION
    path: str | None = None


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes, as 64 lowercase hex digits."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def to_jsonable(obj: Any, where: str = "params") -> Any:
    """Convert numpy arrays and scalars (recursively) to JSON types.

    Raises
    ------
    ModelFileError
        A value that JSON cannot carry: NaN, infinity, or an unknown type.
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v, f"{where}.{k}") for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist(), where)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        if not math.isfinite(x):
            raise ModelFileError(f"cannot save {where} = {x}: not a finite number")
        return x
    if obj is None or isinstance(obj, str):
        return obj
    raise ModelFileError(f"cannot save {where}: {type(obj).__name__} is not JSON data")


def _now_utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def make_provenance(data_paths: Sequence[str], options: Mapping[str, Any],
                    nrmse: Sequence[float | None] | None = None,
                    rows: Sequence[int] | None = None,
                    metrics: Mapping[str, Any] | None = None) -> dict:
    """Build the ``provenance`` object of a model file.

    Parameters
    ----------
    data_paths : sequence of str
        The recordings the model was fitted on (hashed here).
    options : mapping
        Every option of the fit, with its value (defaults included).
    nrmse : sequence of float, optional
        Fit NRMSE (RMS error / range of y, dimensionless) per data file.
    rows : sequence of int, optional
        Rows per data file.
    metrics : mapping, optional
        Further fit figures (e.g. ``{"time_s": 1.2}``).
    """
    data = []
    for i, p in enumerate(data_paths):
        entry = {"path": os.fspath(p), "sha256": file_sha256(p)}
        if rows is not None:
            entry["rows"] = int(rows[i])
        entry["nrmse"] = None if nrmse is None or nrmse[i] is None else float(nrmse[i])
        data.append(entry)
    return {
        "tool": "piezoctl",
        "tool_version": __version__,
        "created": _now_utc(),
        "data": data,
        "options": dict(options),
        "metrics": dict(metrics or {}),
    }


def _check_provenance(prov: Any, where: str) -> None:
    if not isinstance(prov, dict):
        raise ModelFileError(f"{where}: 'provenance' must be an object")
    for key, typ in (("tool_version", str), ("created", str), ("data", list), ("options", dict)):
        if key not in prov:
            raise ModelFileError(f"{where}: provenance lacks '{key}'")
        if not isinstance(prov[key], typ):
            raise ModelFileError(f"{where}: provenance.{key} must be {'a string' if typ is str else 'an ' + ('array' if typ is list else 'object')}")
    for i, entry in enumerate(prov["data"]):
        if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
            raise ModelFileError(f"{where}: provenance.data[{i}] must be an object with a 'path'")
        sha = entry.get("sha256")
        if not isinstance(sha, str) or not _HEX64.match(sha):
            raise ModelFileError(f"{where}: provenance.data[{i}].sha256 must be 64 lowercase hex digits")
        nr = entry.get("nrmse")
        if nr is not None and not (isinstance(nr, (int, float)) and not isinstance(nr, bool)):
            raise ModelFileError(f"{where}: provenance.data[{i}].nrmse must be a number or null")
    if "metrics" in prov and not isinstance(prov["metrics"], dict):
        raise ModelFileError(f"{where}: provenance.metrics must be an object")


def _check_kind(kind: Any, where: str) -> None:
    from ..ident import MODEL_KINDS
    if not isinstance(kind, str):
        raise ModelFileError(f"{where}: 'kind' must be a string")
    if kind not in MODEL_KINDS:
        raise ModelFileError(f"{where}: unknown model kind {kind!r} (known: {', '.join(MODEL_KINDS)})")


def save_model(path: str | os.PathLike, kind: str, params: Mapping[str, Any],
               provenance: Mapping[str, Any]) -> dict:
    """Write a model file.

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    kind : str
        Model kind (a key of :data:`piezoctl.ident.MODEL_KINDS`).
    params : mapping
        The kind's parameters; numpy arrays and scalars are converted.
    provenance : mapping
        As made by :func:`make_provenance`; ``tool_version`` and ``created``
        are filled in when absent.

    Returns
    -------
    dict
        The document written.

    Raises
    ------
    ModelFileError
        Unknown kind, a non-finite or non-JSON value, incomplete provenance,
        or the file cannot be written.
    """
    where = os.fspath(path)
    _check_kind(kind, where)
    prov = dict(provenance)
    prov.setdefault("tool", "piezoctl")
    prov.setdefault("tool_version", __version__)
    prov.setdefault("created", _now_utc())
    prov.setdefault("metrics", {})
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "kind": kind,
        "params": to_jsonable(dict(params), "params"),
        "provenance": to_jsonable(prov, "provenance"),
    }
    _check_provenance(doc["provenance"], where)
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    try:
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
    except OSError as exc:
        raise ModelFileError(f"{where}: cannot write: {exc.strerror or exc}") from None
    return doc


def load_model(path: str | os.PathLike) -> Model:
    """Read and check a model file.

    Raises
    ------
    ModelFileError
        Unreadable file, invalid JSON (with line and column), another
        ``format``, a ``version`` other than 1 (a newer one says so), unknown
        ``kind``, ``params`` not an object, or incomplete ``provenance``;
        JSON nested too deeply; and (a :class:`~piezoctl.io.modelcheck.ModelCheckError`)
        parameters that do not fit their kind (:func:`~piezoctl.io.modelcheck.check_params`:
        types, sizes, ranges, consistency).
    """
    where = os.fspath(path)
    try:
        size = os.path.getsize(path)
        if size > MAX_FILE_BYTES:
            raise ModelFileError(f"{where}: {size} bytes; a model file is at most {MAX_FILE_BYTES} bytes")
        with open(path, "r", encoding="utf-8-sig") as fh:
            text = fh.read()
    except OSError as exc:
        raise ModelFileError(f"{where}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ModelFileError(f"{where}: not a text (UTF-8) file") from None
    try:
        doc = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{where}: line {exc.lineno} column {exc.colno}: invalid JSON: {exc.msg}") from None
    except RecursionError:
        raise ModelFileError(f"{where}: JSON nested too deeply to read (a model file nests at most "
                             f"{MAX_DEPTH} levels)") from None
    except ValueError as exc:
        raise ModelFileError(f"{where}: invalid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ModelFileError(f"{where}: not a piezoctl model file (top level is not an object)")
    if doc.get("format") != FORMAT:
        raise ModelFileError(f"{where}: not a piezoctl model file (format is {doc.get('format')!r}, "
                             f"expected {FORMAT!r})")
    version = doc.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise ModelFileError(f"{where}: 'version' must be an integer, got {version!r}")
    if version > VERSION:
        raise ModelFileError(f"{where}: model file version {version} is newer than this piezoctl "
                             f"{__version__} reads (version {VERSION}); update piezoctl")
    if version != VERSION:
        raise ModelFileError(f"{where}: model file version {version} is not supported (this reads {VERSION})")
    for key in ("kind", "params", "provenance"):
        if key not in doc:
            raise ModelFileError(f"{where}: lacks '{key}'")
    _check_kind(doc["kind"], where)
    if not isinstance(doc["params"], dict):
        raise ModelFileError(f"{where}: 'params' must be an object")
    check_params(doc["kind"], doc["params"], where)
    _check_provenance(doc["provenance"], where)
    return Model(kind=doc["kind"], params=doc["params"], provenance=doc["provenance"],
                 version=version, path=where)


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not allowed (values must be finite numbers)")


def changed_data(model: Model, paths: Iterable[str] | None = None) -> list[str]:
    """Data files of a model's provenance whose SHA-256 no longer matches.

    Files that cannot be read are listed too. ``paths`` overrides where the
    files are looked for (same order as ``provenance.data``).
    """
    entries = model.provenance["data"]
    paths = list(paths) if paths is not None else [e["path"] for e in entries]
    out = []
    for entry, p in zip(entries, paths):
        try:
            if file_sha256(p) != entry["sha256"]:
                out.append(p)
        except OSError:
            out.append(p)
    return out
