"""Recording CSV files: the drive and the measured displacement of one run.

The contract (``docs/recordings.md``)::

    # sample_rate_hz: 10000          optional metadata lines "# key: value"
    # device: stage 3
    t,u,y,u2,x2                      header line: column names
    0,0.0,0.012,0.0,0.0              one row per sample
    0.0001,0.5,0.013,0.0,0.001

Columns (order free, names exact): ``t`` time [s], ``u`` drive command [V],
``y`` measured displacement [um] are required; ``u2`` drive of the other axis
[V], ``x2`` position of the other axis [um], ``reference`` [um] and ``temp``
[degC] are optional; any other column is ignored (and may hold anything).
Every value of a known column must be a finite number and ``t`` must increase
strictly. A file breaking the contract raises :class:`RecordingError` (a
:class:`~piezoctl.errors.CliError`: one line naming the file and the line,
exit status 2 from the CLI).

Non-physical values (the outlier rule, ``docs/recordings.md``): a value of a
signal column outside the range its ``# range_<column>: LO HI`` metadata line
states, or, for a column without such a line, farther than
:data:`OUTLIER_K` robust scales from the column's median, is refused with the
file, line and column. ``load_recording(..., drop_outliers=True)`` drops those
rows instead and lists them in :attr:`Recording.dropped`.
"""

from __future__ import annotations

import dataclasses
import os
import re
from typing import Mapping

import numpy as np

from ..errors import CliError

__all__ = [
    "Recording", "RecordingError", "Outlier", "load_recording", "save_recording", "write_csv",
    "describe_dropped", "robust_limits",
    "REQUIRED_COLUMNS", "OPTIONAL_COLUMNS", "COLUMN_UNITS", "OUTLIER_K", "SCALE_FLOOR", "MAX_TIME_STEP_RATIO",
]

REQUIRED_COLUMNS = ("t", "u", "y")
OPTIONAL_COLUMNS = ("u2", "x2", "reference", "temp")
COLUMN_UNITS = {"t": "s", "u": "V", "y": "um", "u2": "V", "x2": "um",
                "reference": "um", "temp": "degC"}

_META_RE = re.compile(r"^#\s*([A-Za-z0-9_.\-]+)\s*:\s*(.*?)\s*$")

# The outlier rule (docs/recordings.md, "Non-physical values"). A value x of a
# signal column (every known column but t) is non-physical when
#     |x - median| > OUTLIER_K * S,   S = max(1.4826 * MAD, (q99 - q1) / 4.65, SCALE_FLOOR)
# (MAD: median absolute deviation; q1, q99: percentiles; 1.4826 and 4.65 make
# both the standard deviation of a normal signal; SCALE_FLOOR in the column's
# unit keeps a constant column from refusing its first small change). A
# "# range_<column>: LO HI" metadata line replaces the rule for that column by
# LO <= x <= HI (the sensor's or amplifier's range).
OUTLIER_K = 100.0
SCALE_FLOOR = 1.0
# A time step above this multiple of the median step is refused (a t value far
# off, e.g. 1e300 in the last row, keeps t increasing but is not a sample time).
MAX_TIME_STEP_RATIO = 1.0e4


class RecordingError(CliError):
    """A recording file breaks the contract; the message names file and line."""


@dataclasses.dataclass(frozen=True)
class Outlier:
    """One non-physical value: where it is and why it was refused or dropped.

    Attributes
    ----------
    line : int
        1-based line of the file (metadata and header lines counted).
    column : int
        1-based field number in the row.
    name : str
        Column name.
    value : float
        The value read.
    limit : tuple of float
        The accepted interval [lo, hi] of the column.
    rule : str
        ``"range_<name> metadata"`` or ``"robust scale"``.
    """

    line: int
    column: int
    name: str
    value: float
    limit: tuple
    rule: str

    def describe(self) -> str:
        return (f"line {self.line}, column {self.column} {self.name!r}: {self.value:.6g} is outside "
                f"[{self.limit[0]:.6g}, {self.limit[1]:.6g}] ({self.rule})")


@dataclasses.dataclass
class Recording:
    """One recorded run.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time [s], strictly increasing.
    u : ndarray, shape (T,)
        Drive command [V].
    y : ndarray, shape (T,), or None
        Measured displacement [um]; None only when the file was loaded with
        ``require=("t", "u")`` and has no ``y`` (a drive for ``simulate``).
    u2, x2, reference, temp : ndarray, shape (T,), or None
        Drive of the other axis [V], position of the other axis [um],
        reference [um], temperature [degC], where recorded.
    meta : dict of str to str
        The ``# key: value`` metadata lines, in file order.
    path : str or None
        The file it was read from.
    dropped : list of Outlier
        Rows dropped by ``load_recording(..., drop_outliers=True)`` (one entry
        per non-physical value; empty otherwise).
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray | None
    u2: np.ndarray | None = None
    x2: np.ndarray | None = None
    reference: np.ndarray | None = None
    temp: np.ndarray | None = None
    meta: dict = dataclasses.field(default_factory=dict)
    path: str | None = None
    dropped: list = dataclasses.field(default_factory=list)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def dt(self) -> float:
        """Sample period [s]: the median step of ``t``."""
        if len(self) < 2:
            raise RecordingError(f"{self.path or 'recording'}: fewer than 2 samples, no sample period")
        return float(np.median(np.diff(self.t)))

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate [Hz]: the ``sample_rate_hz`` metadata if given, else 1 / :attr:`dt`."""
        value = self.meta.get("sample_rate_hz")
        if value is not None:
            try:
                rate = float(value)
            except ValueError:
                rate = float("nan")
            if not (np.isfinite(rate) and rate > 0):
                raise RecordingError(f"{self.path or 'recording'}: metadata sample_rate_hz "
                                     f"{value!r} is not a positive number")
            return rate
        return 1.0 / self.dt

    def columns(self) -> dict:
        """The recorded columns (required and present optional ones) by name."""
        out = {name: getattr(self, name) for name in REQUIRED_COLUMNS if getattr(self, name) is not None}
        for name in OPTIONAL_COLUMNS:
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        return out


def _fail(path: str, lineno: int | None, msg: str) -> RecordingError:
    where = f"{path}: line {lineno}" if lineno is not None else f"{path}"
    return RecordingError(f"{where}: {msg}")


def _read_head(path: str, lines: list[str]) -> tuple[dict, list[str], int]:
    """Parse metadata and header; return (meta, column names, index of the header line)."""
    meta: dict[str, str] = {}
    for i, raw in enumerate(lines):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            m = _META_RE.match(line)
            if m:
                meta[m.group(1)] = m.group(2)
            continue
        names = [c.strip() for c in line.split(",")]
        return meta, names, i
    raise _fail(path, None, "no header line (expected a line of column names such as 't,u,y')")


def _locate_bad_row(path: str, lines: list[str], first: int, ncols: int,
                    use: dict[str, int]) -> RecordingError:
    """Slow path: find the first data line that does not parse and describe it."""
    for i in range(first, len(lines)):
        line = lines[i].strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split(",")
        if len(fields) != ncols:
            return _fail(path, i + 1, f"{len(fields)} fields, header has {ncols}")
        for name, col in use.items():
            try:
                float(fields[col])
            except ValueError:
                return _fail(path, i + 1, f"column {col + 1} {name!r}: {fields[col].strip()!r} is not a number")
    return _fail(path, None, "data could not be parsed")


def _scan_body(body: list[str]):
    """(keep, commas) per line of ``body``: whether it is a data line (not blank, not a comment) and its number
    of commas, by array operations over the lines' bytes; None when the lines are not all ASCII (the caller
    then tests each line in Python, the general path).

    The two Python tests per line they replace took about 0.5 s per million lines (more than ``np.loadtxt``'s
    conversion). The lines are joined with LF; as ``str.splitlines`` made them, none holds a line break, so
    each LF ends exactly one line. A line whose first byte is a space or tab (rare) is tested in Python."""
    if not body:
        return None
    joined = "\n".join(body) + "\n"
    if not joined.isascii():
        return None
    b = np.frombuffer(joined.encode("ascii"), dtype=np.uint8)
    ends = np.flatnonzero(b == 0x0A)
    if ends.size != len(body):
        return None
    starts = np.empty_like(ends)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    lead = b[starts]
    keep = (lead != ord("#")) & (lead != 0x0A)
    for i in np.flatnonzero(lead <= 0x20):   # whitespace first (str.strip's whitespace is all <= 0x20 in ASCII)
        s = body[i]
        keep[i] = bool(s.strip()) and not s.lstrip().startswith("#")
    commas = np.diff(np.searchsorted(np.flatnonzero(b == ord(",")), ends), prepend=0)
    return keep, commas


def _sample_rate_meta(path: str, meta: dict, meta_lines: dict) -> None:
    value = meta.get("sample_rate_hz")
    if value is None:
        return
    try:
        rate = float(value)
    except ValueError:
        rate = float("nan")
    if not (np.isfinite(rate) and rate > 0):
        raise _fail(path, meta_lines.get("sample_rate_hz"),
                    f"metadata sample_rate_hz {value!r} is not a positive finite number [Hz]")


def _meta_ranges(path: str, meta: dict, meta_lines: dict, names: list[str]) -> dict:
    """The ``range_<column>: LO HI`` metadata lines as {column: (lo, hi)}."""
    out = {}
    for key, value in meta.items():
        if not key.startswith("range_"):
            continue
        col = key[len("range_"):]
        line = meta_lines.get(key)
        if col not in COLUMN_UNITS or col == "t":
            raise _fail(path, line, f"metadata {key}: {col!r} is not a signal column "
                                    f"({', '.join(c for c in COLUMN_UNITS if c != 't')})")
        parts = [p for p in re.split(r"[\s,;]+|\.\.", value.strip()) if p]
        try:
            lo, hi = (float(p) for p in parts)
        except ValueError:
            raise _fail(path, line, f"metadata {key}: {value!r} is not two numbers 'LO HI' "
                                    f"[{COLUMN_UNITS[col]}]") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise _fail(path, line, f"metadata {key}: {value!r} is not a range LO < HI of finite numbers")
        out[col] = (lo, hi)
    return out


def robust_limits(x: np.ndarray) -> tuple[float, float]:
    """The interval the outlier rule accepts for a column without a stated range.

    ``median -+ OUTLIER_K * S`` with ``S = max(1.4826 * MAD, (q99 - q1) / 4.65,
    SCALE_FLOOR)`` (docs/recordings.md).
    """
    med = float(np.median(x))
    mad = float(np.median(np.abs(x - med)))
    q1, q99 = np.percentile(x, [1.0, 99.0])
    scale = max(1.4826 * mad, float(q99 - q1) / 4.65, SCALE_FLOOR)
    return med - OUTLIER_K * scale, med + OUTLIER_K * scale


def _find_outliers(data: np.ndarray, use: dict[str, int], lineno: np.ndarray,
                   ranges: dict) -> list[Outlier]:
    found = []
    for j, (name, col) in enumerate(use.items()):
        if name == "t":
            continue
        x = data[:, j]
        if name in ranges:
            lo, hi = ranges[name]
            rule = f"range_{name} metadata"
        else:
            lo, hi = robust_limits(x)
            rule = f"more than {OUTLIER_K:g} robust scales from the median"
        for r in np.nonzero((x < lo) | (x > hi))[0]:
            found.append(Outlier(line=int(lineno[r]), column=col + 1, name=name, value=float(x[r]),
                                 limit=(lo, hi), rule=rule))
    found.sort(key=lambda o: (o.line, o.column))
    return found


def describe_dropped(rec: Recording, limit: int = 5) -> str:
    """One line saying which values ``--drop-outliers`` dropped from ``rec`` (empty if none)."""
    if not rec.dropped:
        return ""
    rows = len({o.line for o in rec.dropped})
    where = "; ".join(o.describe() for o in rec.dropped[:limit])
    more = f"; and {len(rec.dropped) - limit} more" if len(rec.dropped) > limit else ""
    return f"{rec.path}: dropped {rows} row(s) with non-physical values: {where}{more}"


def load_recording(path: str | os.PathLike, *, require: tuple = REQUIRED_COLUMNS,
                   drop_outliers: bool = False) -> Recording:
    """Read a recording CSV file (see the module docstring for the contract).

    Parameters
    ----------
    path : str or path-like
        The CSV file.
    require : tuple of str
        Columns that must be present: ``("t", "u", "y")`` (default) or
        ``("t", "u")`` for a drive that a model is to be run on.
    drop_outliers : bool
        Drop the rows holding non-physical values (listed in
        :attr:`Recording.dropped`) instead of refusing the file.

    Returns
    -------
    Recording
        Arrays in float64 and the metadata.

    Raises
    ------
    RecordingError
        Missing file, no header, a required column missing, a duplicated
        column, a field that is not a number, a non-finite value, fewer than two
        rows, time not strictly increasing or jumping (more than
        :data:`MAX_TIME_STEP_RATIO` median steps), a malformed
        ``sample_rate_hz`` or ``range_<column>`` metadata line, or a
        non-physical value (the outlier rule) unless ``drop_outliers``. The
        message is one line naming the file and, where it applies, the line
        number (1-based, counting metadata and header lines) and the column.
        A UTF-8 byte order mark is accepted.
    """
    path = os.fspath(path)
    try:
        with open(path, "r", encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise _fail(path, None, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise _fail(path, None, "not a text (UTF-8) file") from None

    meta, names, hdr = _read_head(path, lines)
    meta_lines = {}
    for i in range(hdr):
        m = _META_RE.match(lines[i].strip())
        if m:
            meta_lines[m.group(1)] = i + 1
    _sample_rate_meta(path, meta, meta_lines)
    seen = set()
    for name in names:
        if name in seen and name in COLUMN_UNITS:
            raise _fail(path, hdr + 1, f"column {name!r} appears twice in the header")
        seen.add(name)
    missing = [c for c in require if c not in names]
    if missing:
        stray = [n for n in names if n.lstrip("\ufeff\ufffe").strip() != n]
        hint = f"; column name(s) {', '.join(map(repr, stray))} carry a stray byte order mark" if stray else ""
        raise _fail(path, hdr + 1, f"header lacks column(s) {', '.join(missing)} "
                                   f"(required: {', '.join(require)}; found: {','.join(names)}){hint}")
    use = {name: names.index(name) for name in REQUIRED_COLUMNS + OPTIONAL_COLUMNS if name in names}
    ranges = _meta_ranges(path, meta, meta_lines, names)

    # Data lines and their 1-based line numbers (blank and comment lines skipped).
    first = hdr + 1
    body = lines[first:]
    scan = _scan_body(body)
    if scan is None:   # the general path: a Python test per line
        keep = np.fromiter((bool(s.strip()) and not s.lstrip().startswith("#") for s in body),
                           dtype=bool, count=len(body))
    else:
        keep, commas = scan
    lineno = np.nonzero(keep)[0] + first + 1
    if lineno.size < 2:
        raise _fail(path, None, f"{lineno.size} data row(s); a recording needs at least 2")
    data_lines = body if keep.all() else [s for s, k in zip(body, keep) if k]

    cols = list(use.values())
    try:
        data = np.loadtxt(data_lines, delimiter=",", usecols=cols, dtype=np.float64, ndmin=2,
                          comments=None)
    except ValueError:
        raise _locate_bad_row(path, lines, first, len(names), use) from None
    # loadtxt only checks the columns it converts; every row must still have all fields.
    if scan is None:
        nfields = np.fromiter((s.count(",") for s in data_lines), dtype=np.int64, count=len(data_lines))
    else:
        nfields = commas[keep]
    bad = np.nonzero(nfields != len(names) - 1)[0]
    if bad.size:
        r = int(bad[0])
        raise _fail(path, int(lineno[r]), f"{nfields[r] + 1} fields, header has {len(names)}")

    finite = np.isfinite(data)
    if not finite.all():
        r, c = np.argwhere(~finite)[0]
        name = list(use)[c]
        raise _fail(path, int(lineno[r]), f"column {use[name] + 1} {name!r} is {float(data[r, c])!r} "
                                          f"(values must be finite numbers)")
    t = data[:, list(use).index("t")]
    step = np.diff(t)
    bad = np.nonzero(step <= 0)[0]
    if bad.size:
        r = int(bad[0]) + 1
        raise _fail(path, int(lineno[r]), f"time not increasing: t = {float(t[r])!r} s after {float(t[r - 1])!r} s")
    med_step = float(np.median(step))
    bad = np.nonzero(step > MAX_TIME_STEP_RATIO * med_step)[0]
    if bad.size:
        r = int(bad[0]) + 1
        raise _fail(path, int(lineno[r]), f"column {use['t'] + 1} 't': time jumps from {float(t[r - 1])!r} s "
                                          f"to {float(t[r])!r} s, more than {MAX_TIME_STEP_RATIO:g} times "
                                          f"the median step {med_step:.6g} s")

    outliers = _find_outliers(data, use, lineno, ranges)
    dropped: list[Outlier] = []
    if outliers:
        if not drop_outliers:
            more = f" (and {len(outliers) - 1} more)" if len(outliers) > 1 else ""
            raise _fail(path, outliers[0].line,
                        f"column {outliers[0].column} {outliers[0].name!r}: non-physical value "
                        f"{outliers[0].value:.6g}, outside [{outliers[0].limit[0]:.6g}, "
                        f"{outliers[0].limit[1]:.6g}] ({outliers[0].rule}){more}; "
                        f"--drop-outliers drops such rows")
        bad_rows = np.isin(lineno, [o.line for o in outliers])
        data = data[~bad_rows]
        dropped = outliers
        if data.shape[0] < 2:
            raise _fail(path, None, f"{data.shape[0]} data row(s) left after dropping "
                                    f"{len(outliers)} non-physical value(s); a recording needs at least 2")

    arrays = {name: np.ascontiguousarray(data[:, j]) for j, name in enumerate(use)}
    arrays.setdefault("y", None)
    return Recording(meta=meta, path=path, dropped=dropped, **arrays)


def _fmt_block(block: np.ndarray, fmt_row: str) -> str:
    return (fmt_row * block.shape[0]) % tuple(block.ravel().tolist())


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray],
              meta: Mapping[str, object] | None = None, precision: int = 10) -> None:
    """Write columns as CSV: ``# key: value`` metadata lines, header, rows.

    The general writer behind :func:`save_recording`; it requires no column
    (``piezoctl simulate`` writes ``t,y`` with it).

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    columns : mapping of str to array_like
        Columns in the order to write, all of the same length.
    meta : mapping, optional
        Metadata lines.
    precision : int
        Significant digits per value (default 10).

    Raises
    ------
    RecordingError
        Columns of different lengths, a bad column name, a metadata key or
        value that would not read back, or the file cannot be written.
    """
    path = os.fspath(path)
    order = list(columns)
    arrays = [np.asarray(columns[c], dtype=np.float64).reshape(-1) for c in order]
    if not arrays:
        raise RecordingError(f"{path}: cannot save, no columns")
    n = arrays[0].shape[0]
    if any(a.shape[0] != n for a in arrays):
        raise RecordingError(f"{path}: cannot save, columns have different lengths "
                             f"({', '.join(f'{c}={a.shape[0]}' for c, a in zip(order, arrays))})")
    for c in order:
        if "," in c or "\n" in c or not c.strip() or c.strip().startswith("#"):
            raise RecordingError(f"{path}: cannot save, bad column name {c!r}")
    data = np.column_stack(arrays)
    fmt_row = ",".join([f"%.{precision}g"] * len(order)) + "\n"
    try:
        with open(path, "w", encoding="utf-8", newline="\n") as fh:
            for key, value in (meta or {}).items():
                text = str(value)
                if not re.fullmatch(r"[A-Za-z0-9_.\-]+", str(key)) or "\n" in text:
                    raise RecordingError(f"{path}: cannot save metadata {key!r}: {text!r}")
                fh.write(f"# {key}: {text}\n")
            fh.write(",".join(order) + "\n")
            chunk = 50_000
            for i in range(0, n, chunk):
                fh.write(_fmt_block(data[i:i + chunk], fmt_row))
    except OSError as exc:
        raise RecordingError(f"{path}: cannot write: {exc.strerror or exc}") from None


def save_recording(path: str | os.PathLike, rec: Recording | Mapping[str, np.ndarray],
                   meta: Mapping[str, object] | None = None, precision: int = 10) -> None:
    """Write a recording CSV file that :func:`load_recording` reads back.

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    rec : Recording or mapping of str to array_like
        The columns: a :class:`Recording`, or a mapping with at least ``t``
        [s], ``u`` [V], ``y`` [um] and optionally the other known columns or
        any other column (written after the known ones, as given).
    meta : mapping, optional
        Metadata written as ``# key: value`` lines; for a :class:`Recording`
        its own ``meta`` is used when this is None.
    precision : int
        Significant digits per value (default 10).

    Raises
    ------
    RecordingError
        Columns of different lengths, a required column missing, or a key or
        value that would not read back.
    """
    path = os.fspath(path)
    if isinstance(rec, Recording):
        cols = rec.columns()
        if meta is None:
            meta = rec.meta
    else:
        cols = dict(rec)
    missing = [c for c in REQUIRED_COLUMNS if c not in cols]
    if missing:
        raise RecordingError(f"{path}: cannot save, column(s) {', '.join(missing)} missing")
    order = [c for c in REQUIRED_COLUMNS + OPTIONAL_COLUMNS if c in cols]
    order += [c for c in cols if c not in order]
    write_csv(path, {c: cols[c] for c in order}, meta=meta, precision=precision)


def session_start(rec) -> float | None:
    """The recording's first sample on the session's clock [s] (metadata ``session_time_s``: seconds since the
    stage was powered or the session began, as the recorder stamps it), or None when the recording has none.
    Slow effects that run on wall time (thermal drift) are modelled on this clock."""
    value = getattr(rec, "meta", {}).get("session_time_s")
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def sensor_session(rec) -> str | None:
    """The recording's sensor session (metadata ``session``: any label; recordings with the same label share the
    sensor's zero, i.e. the sensor was not re-zeroed, remounted or re-powered between them), or None."""
    value = getattr(rec, "meta", {}).get("session")
    if value is None:
        return None
    value = str(value).strip()
    return value or None
