"""Two ``diagnosis.json`` compared, every value: ``tools/diff-diagnosis A.json B.json [--rtol R]``.

For a speed change that must not change the diagnosis (docs/diagnose-speed.md, "Round 13"): every string, bool,
key and list length must be equal (paths by their file name: the same case read from two directories), every
number within ``--rtol`` relative (default 1e-9). The run's own wall time (``time_s``) is skipped. Prints each
difference beyond the tolerance and one summary line; exit 0 when none, 1 otherwise, 2 for unreadable input.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

__all__ = ["compare", "main"]

SKIP = ("time_s",)   # the run's own wall time


def _walk(a, b, path: str, out: dict) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in SKIP:
                continue
            if k not in a or k not in b:
                out["struct"].append(f"{path}/{k}: only in {'A' if k in a else 'B'}")
            else:
                _walk(a[k], b[k], f"{path}/{k}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out["struct"].append(f"{path}: {len(a)} items against {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            _walk(x, y, f"{path}[{i}]", out)
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool) \
            and not isinstance(b, bool):
        if a == b or (math.isnan(a) and math.isnan(b)):
            return
        out["numbers"].append((abs(a - b) / max(abs(a), abs(b)), path, a, b))
    else:
        if isinstance(a, str) and isinstance(b, str) and "/" in a and "/" in b:
            a, b = a.rsplit("/", 1)[-1], b.rsplit("/", 1)[-1]
        if a != b or type(a) is not type(b):
            out["struct"].append(f"{path}: {a!r} against {b!r}")


def compare(a: dict, b: dict, rtol: float = 1e-9) -> dict:
    """Differences of two diagnosis documents.

    Returns
    -------
    dict
        ``struct``: differing strings, bools, keys, lengths and types (list of str); ``beyond``: numbers differing
        by more than ``rtol`` relative, largest first, as (relative difference, path, a, b); ``n_numbers_differ``:
        numbers differing at all; ``max_rel``: the largest relative difference (0.0 when none).
    """
    out = {"struct": [], "numbers": []}
    _walk(a, b, "", out)
    beyond = sorted((x for x in out["numbers"] if x[0] > rtol), reverse=True)
    return {"struct": out["struct"], "beyond": beyond, "n_numbers_differ": len(out["numbers"]),
            "max_rel": max((x[0] for x in out["numbers"]), default=0.0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="diff-diagnosis", description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance on numbers (default 1e-9)")
    args = ap.parse_args(argv)
    try:
        docs = [json.load(open(p)) for p in (args.a, args.b)]
    except (OSError, ValueError) as e:
        print(f"diff-diagnosis: error: {e}", file=sys.stderr)
        return 2
    r = compare(*docs, rtol=args.rtol)
    for s in r["struct"]:
        print(f"differs {s}")
    for rel, path, x, y in r["beyond"]:
        print(f"number {path}: {x!r} against {y!r} (relative {rel:.2e})")
    print(f"{r['n_numbers_differ']} numbers differ at all, {len(r['beyond'])} beyond {args.rtol:g} relative (largest "
          f"{r['max_rel']:.2e}); {len(r['struct'])} other differences")
    return 1 if r["struct"] or r["beyond"] else 0


if __name__ == "__main__":
    sys.exit(main())
