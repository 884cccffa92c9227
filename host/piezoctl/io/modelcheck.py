"""Checks of a model file's ``params`` on load: types, sizes and consistency per kind.

A model file is data from outside: it may be hand-edited, truncated, or made to
hurt (``"L": 100000`` asks for a 37 GiB buffer, a ``null`` weight gives NaN
output, ``u_min == u_max`` divides by zero). :func:`check_params` refuses such
a file before any array is allocated, with a :class:`ModelFileError` naming the
file and the JSON path of the field (``docs/model-file.md``, "Checks on load").

The checks, for every kind:

- nesting at most :data:`MAX_DEPTH` levels, at most :data:`MAX_NUMBERS`
  numbers in all;
- no ``null`` inside an array of numbers, no string or boolean where a number
  is expected (``"L": "10"`` is refused, not converted);
- ``u_min < u_max`` where both are given (an inverted or empty drive range);
- ``input_delay_s`` a number in [0, :data:`MAX_DELAY_S`].

and per kind the fields its ``simulate`` reads (:data:`KIND_CHECKS`), with the
sizes bounded (:data:`MAX_KP_LEVELS`, :data:`MAX_OPERATORS`) and the array
lengths consistent (``N == L (L + 1) / 2 == len(w)``, ``len(alpha) == n``, ...).
:func:`work_columns` gives the number of float64 values per sample that a
kind's simulation holds, so that ``simulate`` can bound ``T x columns``
before it runs.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from ..errors import CliError

__all__ = ["ModelFileError", "ModelCheckError", "check_params", "check_depth", "work_columns",
           "MAX_DEPTH", "MAX_NUMBERS", "MAX_KP_LEVELS", "MAX_OPERATORS", "MAX_DELAY_S", "KIND_CHECKS"]

MAX_DEPTH = 32            # JSON nesting levels (a model file uses at most 5)
MAX_NUMBERS = 5_000_000   # numbers in params (a 100-level KP grid has 5050 weights)
MAX_KP_LEVELS = 100       # KP/RKP grid intervals per axis: N = L (L + 1) / 2 <= 5050 operators
MAX_OPERATORS = 5050      # operators of any kind (KP cells, RKP N x M, plays, CPI/UPI)
MAX_DELAY_S = 10.0        # input_delay_s [s]


class ModelFileError(CliError):
    """A model file is missing, malformed, of another format or version."""


class ModelCheckError(ModelFileError):
    """A model file's parameters are malformed (the message names file and field)."""


def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


class _Checker:
    def __init__(self, where: str, params: dict):
        self.where = where
        self.p = params

    def fail(self, field: str, msg: str) -> ModelCheckError:
        return ModelCheckError(f"{self.where}: params.{field}: {msg}")

    def get(self, field: str, optional: bool = False):
        node: Any = self.p
        for part in field.split("."):
            if not isinstance(node, dict) or part not in node:
                if optional:
                    return None
                raise self.fail(field, "missing")
            node = node[part]
        return node

    def num(self, field: str, lo: float = -math.inf, hi: float = math.inf, optional: bool = False,
            positive: bool = False, nonzero: bool = False):
        x = self.get(field, optional)
        if x is None:
            if optional:
                return None
            raise self.fail(field, "is null, expected a number")
        if not _is_num(x):
            raise self.fail(field, f"{x!r} is not a number ({type(x).__name__})")
        x = float(x)
        if not math.isfinite(x):
            raise self.fail(field, f"{x} is not finite")
        if positive and not x > 0:
            raise self.fail(field, f"{x:g} must be > 0")
        if nonzero and x == 0:
            raise self.fail(field, "must not be 0")
        if not lo <= x <= hi:
            raise self.fail(field, f"{x:g} is outside [{lo:g}, {hi:g}]")
        return x

    def int(self, field: str, lo: int, hi: int, optional: bool = False):
        x = self.get(field, optional)
        if x is None and optional:
            return None
        if not isinstance(x, int) or isinstance(x, bool):
            raise self.fail(field, f"{x!r} is not an integer (a JSON number without quotes)")
        if not lo <= x <= hi:
            raise self.fail(field, f"{x} is outside [{lo}, {hi}]")
        return x

    def vec(self, field: str, length: int | None = None, optional: bool = False, min_len: int = 0,
            max_len: int = MAX_OPERATORS, what: str = "values"):
        x = self.get(field, optional)
        if x is None and optional:
            return None
        return self._vec(field, x, length, min_len, max_len, what)

    def _vec(self, field, x, length=None, min_len=0, max_len=MAX_OPERATORS, what="values"):
        if not isinstance(x, list):
            raise self.fail(field, f"expected an array of numbers, got {type(x).__name__}")
        for i, e in enumerate(x):
            if not _is_num(e):
                raise self.fail(f"{field}[{i}]", f"{e!r} is not a number" if e is not None else "is null")
        if length is not None and len(x) != length:
            raise self.fail(field, f"{len(x)} {what}, expected {length}")
        if not min_len <= len(x) <= max_len:
            raise self.fail(field, f"has {len(x)} values, expected {min_len} to {max_len}")
        return x

    def mat(self, field: str, rows: int | None = None, cols: int | None = None, optional: bool = False):
        x = self.get(field, optional)
        if x is None and optional:
            return None
        if not isinstance(x, list):
            raise self.fail(field, f"expected an array of arrays, got {type(x).__name__}")
        if rows is not None and len(x) != rows:
            raise self.fail(field, f"has {len(x)} rows, expected {rows}")
        width = cols
        for i, row in enumerate(x):
            self._vec(f"{field}[{i}]", row, width)
            width = len(row) if width is None else width
        return x

    def u_range(self, lo: str = "u_min", hi: str = "u_max"):
        a = self.num(lo)
        b = self.num(hi)
        if a == b:
            raise self.fail(f"{lo}/{hi}", f"empty drive range ({lo} == {hi} == {a:g} V)")
        if a > b:
            raise self.fail(f"{lo}/{hi}", f"inverted drive range ({lo} {a:g} V > {hi} {b:g} V)")


def _kp_grid(c: _Checker) -> int:
    L = c.int("L", 1, MAX_KP_LEVELS)
    nmin = c.num("nmin")
    nmax = c.num("nmax", positive=True)
    if not nmin < nmax:
        raise c.fail("nmin/nmax", f"nmin {nmin:g} must be < nmax {nmax:g}")
    c.num("s", optional=True, positive=True)
    n = L * (L + 1) // 2
    if "N" in c.p:
        N = c.int("N", 1, MAX_OPERATORS)
        if N != n:
            raise c.fail("N", f"{N} operators, but L = {L} gives L (L + 1) / 2 = {n}")
    return n


def _check_kp(c: _Checker) -> None:
    c.u_range()
    n = _kp_grid(c)
    c.vec("w", n, what=f"weights w for a grid of {n} operators")
    c.num("linear", optional=True)
    c.num("offset")


def _check_rkp(c: _Checker) -> None:
    c.u_range()
    n = _kp_grid(c)
    M = c.int("M", 1, 64)
    if n * M > MAX_OPERATORS * 4:
        raise c.fail("M", f"N x M = {n * M} weights exceed {MAX_OPERATORS * 4}")
    c.mat("theta", n, M)
    c.vec("centers", M)
    widths = c.vec("widths", M)
    if any(w <= 0 for w in widths):
        raise c.fail("widths", "every width must be > 0")
    c.vec("theta_lin", M, optional=True)
    c.num("rate_cutoff_hz", optional=True, positive=True)
    c.num("offset")


def _check_eupi(c: _Checker) -> None:
    c.u_range()
    c.num("y_mid")
    c.num("y_half", nonzero=True)
    c.num("a0")
    n_cpi = len(c.vec("r_cpi", min_len=0))
    c.vec("b", n_cpi)
    n_upi = len(c.vec("r_upi"))
    n_a = len(c.vec("a_upi"))
    if n_upi * n_a > MAX_OPERATORS:
        raise c.fail("d", f"{n_upi} x {n_a} UPI operators exceed {MAX_OPERATORS}")
    c.mat("d", n_upi, n_a if n_upi else None)
    c.vec("p")
    c.num("p0")
    c.num("k_ex", optional=True)


def _check_preisach(c: _Checker) -> None:
    c.u_range()
    n = c.int("n", 1, MAX_OPERATORS)
    c.vec("alpha", n, what=f"weights alpha for n = {n}")
    c.num("p1")
    c.num("p2")
    c.num("offset")


def _check_cascade(c: _Checker) -> None:
    hyst = c.get("hysteresis")
    if not isinstance(hyst, dict):
        raise c.fail("hysteresis", "expected an object (eupi parameters)")
    _check_eupi(_Sub(c, "hysteresis", hyst))
    c.vec("num", min_len=1, max_len=64)
    den = c.vec("den", min_len=1, max_len=64)
    if den[0] == 0:
        raise c.fail("den[0]", "leading denominator coefficient must not be 0")
    c.num("c0", optional=True)
    c.num("c1", optional=True)


def _check_refined(c: _Checker) -> None:
    c.num("u_mid")
    c.num("u_half", positive=True)
    c.num("fs_hz", positive=True, optional=True)
    hyst = c.get("hysteresis")
    if not isinstance(hyst, dict):
        raise c.fail("hysteresis", "expected an object")
    if hyst.get("type") == "plane":   # the diagnosis base: per play threshold, increasing knots and their values
        r, knots, values = hyst.get("r"), hyst.get("knots"), hyst.get("values")
        if not (isinstance(r, list) and isinstance(knots, list) and isinstance(values, list)) or not r \
                or not len(r) == len(knots) == len(values) or len(r) > 64:
            raise c.fail("hysteresis.r", "plane: r, knots and values must be lists of one length (1..64)")
        for j, (kn, va) in enumerate(zip(knots, values)):
            if not (isinstance(kn, list) and isinstance(va, list)) or not 2 <= len(kn) == len(va) <= 256:
                raise c.fail(f"hysteresis.knots[{j}]", "plane: 2..256 knots with one value each")
            if any(not isinstance(x, (int, float)) for x in kn + va) or any(b <= a for a, b in zip(kn, kn[1:])):
                raise c.fail(f"hysteresis.knots[{j}]", "plane: knots must be numbers, strictly increasing")
    dyn = c.get("dynamics")
    if not isinstance(dyn, dict):
        raise c.fail("dynamics", "expected an object")
    c.vec("dynamics.b", min_len=1, max_len=64)
    a = c.vec("dynamics.a", min_len=1, max_len=64)
    if a[0] == 0:
        raise c.fail("dynamics.a[0]", "leading denominator coefficient must not be 0")


def _check_hammerstein(c: _Checker) -> None:
    pass  # generic checks only (numbers finite, no null in arrays, sizes bounded)


class _Sub(_Checker):
    """A checker for a nested parameter object whose messages keep the full path."""

    def __init__(self, parent: _Checker, prefix: str, params: dict):
        super().__init__(parent.where, params)
        self.prefix = prefix

    def fail(self, field: str, msg: str) -> ModelCheckError:
        return ModelCheckError(f"{self.where}: params.{self.prefix}.{field}: {msg}")


KIND_CHECKS: dict[str, Callable[[_Checker], None]] = {
    "kp": _check_kp, "rkp": _check_rkp, "eupi": _check_eupi, "preisach": _check_preisach,
    "cascade": _check_cascade, "refined": _check_refined, "hammerstein": _check_hammerstein,
}


def check_depth(doc: Any, where: str, limit: int = MAX_DEPTH) -> None:
    """Refuse nesting deeper than ``limit`` and more than :data:`MAX_NUMBERS` numbers (iterative)."""
    stack = [(doc, 1, "")]
    count = 0
    while stack:
        node, depth, path = stack.pop()
        if depth > limit:
            raise ModelCheckError(f"{where}: {path or 'top level'}: nested deeper than {limit} levels")
        if isinstance(node, dict):
            stack.extend((v, depth + 1, f"{path}.{k}" if path else str(k)) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, depth + 1, f"{path}[{i}]") for i, v in enumerate(node))
        elif _is_num(node):
            count += 1
            if count > MAX_NUMBERS:
                raise ModelCheckError(f"{where}: more than {MAX_NUMBERS} numbers; not a model file")


def _null_in_numbers(node: Any, path: str) -> str | None:
    """The path of the first null inside an array that otherwise holds numbers (iterative)."""
    stack = [(node, path)]
    while stack:
        x, p = stack.pop()
        if isinstance(x, dict):
            stack.extend((v, f"{p}.{k}") for k, v in x.items())
        elif isinstance(x, list):
            if any(_is_num(e) for e in x):
                for i, e in enumerate(x):
                    if e is None:
                        return f"{p}[{i}]"
            stack.extend((v, f"{p}[{i}]") for i, v in enumerate(x) if isinstance(v, (list, dict)))
    return None


def check_params(kind: str, params: dict, where: str) -> None:
    """Check a model's ``params`` for its kind; raise :class:`ModelCheckError` naming the field.

    Parameters
    ----------
    kind : str
        Model kind (already checked to be known).
    params : dict
        The parameters as loaded from JSON.
    where : str
        The file, for messages.
    """
    check_depth(params, where)
    bad = _null_in_numbers(params, "params")
    if bad:
        raise ModelCheckError(f"{where}: {bad}: is null, expected a number")
    c = _Checker(where, params)
    c.num("input_delay_s", 0.0, MAX_DELAY_S, optional=True)
    if "u_min" in params or "u_max" in params:
        c.u_range()
    KIND_CHECKS.get(kind, lambda _c: None)(c)


def work_columns(kind: str, params: dict) -> int:
    """Float64 values per sample that the kind's simulation holds at once (an upper estimate).

    ``simulate`` refuses ``samples x work_columns`` above its memory budget
    before running the model.
    """
    if kind in ("kp",):
        return 1 + int(params.get("N") or 0)
    if kind == "rkp":
        return 1 + int(params.get("N") or 0) * (1 + int(params.get("M") or 1))
    if kind == "preisach":
        return 3 + int(params.get("n") or 0)
    if kind in ("eupi", "cascade"):
        p = params.get("hysteresis", params) if kind == "cascade" else params
        return 4 + len(p.get("r_cpi") or []) + len(p.get("r_upi") or []) * max(1, len(p.get("a_upi") or []))
    return 16
