"""``piezoctl diagnose``: locate and name the physics a simulation leaves out (docs/diagnose.md).

``--calibration`` recordings fit the base model (hysteresis plus linear dynamics);
``--recordings`` are the data it does not match. Writes ``DIR/diagnosis.json``,
``DIR/base_model.json``, ``DIR/refined_model.json`` (kind ``refined``; both run
with ``piezoctl simulate --model``) and ``DIR/report.html``.

This wrapper checks the inputs before the diagnosis runs: every recording is
loaded once here (the loader's checks, the outlier rule; ``--drop-outliers``
drops and reports), the recordings must share one sample rate (the message
names the file that differs) and be long enough (:data:`MIN_SETTLED_SAMPLES`
samples after ``--settle-s``). The diagnosis writes into a sibling temporary
directory that becomes ``DIR`` only when it succeeds: a failed run leaves no
partial output (and an existing ``DIR`` as it was).

Output: progress on stderr (the notation is explained in docs/diagnose.md,
"Console output"), then the result on stdout: the named effects, the NRMSE
before and after, the drive's discontinuities and where the files are; with
``--json`` the same as one JSON object (:func:`result_of`); ``--quiet`` drops
the progress.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

from ..errors import CliError
from ._options import add_output, emit, progress

__all__ = ["add_parser", "run", "check_inputs", "result_of", "MIN_SETTLED_SAMPLES", "RATE_TOLERANCE"]

# Samples each recording needs after --settle-s: the diagnosis splits every
# recording into at least 6 cross-validation blocks and fits filters per block.
MIN_SETTLED_SAMPLES = 600
RATE_TOLERANCE = 0.01   # relative sample-rate difference accepted between recordings


def add_parser(sub) -> None:
    p = sub.add_parser("diagnose", help="locate a model/data mismatch, name the missing physics, model it",
                       description="Fit a base model (hysteresis + linear dynamics) on calibration recordings, "
                                   "find where it fails on further recordings, name the physics left out, add "
                                   "it and show the held-out improvement (docs/diagnose.md).")
    p.add_argument("--calibration", required=True, nargs="+", metavar="C.csv", help="calibration recordings")
    p.add_argument("--recordings", required=True, nargs="+", metavar="R.csv",
                   help="recordings the simulation does not match")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--settle-s", type=float, default=0.5, metavar="S",
                   help="seconds at the start of every recording left out of fits and scores (default 0.5)")
    p.add_argument("--max-terms", type=int, default=4, metavar="N", help="at most N added terms (default 4)")
    p.add_argument("--drop-outliers", action="store_true",
                   help="drop rows with non-physical values (docs/recordings.md) and say where, instead of "
                        "refusing the file; the cleaned copies are kept in DIR/cleaned/")
    p.add_argument("--no-report", action="store_true", help="skip report.html")
    p.add_argument("--png", action="store_true", help="also write the report's figures as DIR/plots/*.png")
    add_output(p, json_help="print the result (named effects, NRMSE, drive discontinuities, files) as one JSON "
                            "object on stdout")
    p.set_defaults(func=run)


def check_inputs(paths: list[str], settle_s: float, drop_outliers: bool = False) -> list:
    """Load every recording once and check what the diagnosis needs; return the recordings.

    Raises
    ------
    CliError
        A recording the loader refuses, a sample rate differing from the
        first file's (naming both files), or too few samples after settling.
    """
    from ..io.recording import describe_dropped, load_recording
    recs = [load_recording(p, drop_outliers=drop_outliers) for p in paths]
    ref = recs[0]
    for r in recs:
        if r.dropped:
            print(describe_dropped(r), file=sys.stderr)
        n_settle = int(round(settle_s * r.sample_rate_hz))
        if len(r) - n_settle < MIN_SETTLED_SAMPLES:
            raise CliError(f"{r.path}: {len(r)} samples, {max(len(r) - n_settle, 0)} after --settle-s {settle_s:g}; "
                           f"diagnose needs at least {MIN_SETTLED_SAMPLES} after settling")
        if abs(r.sample_rate_hz / ref.sample_rate_hz - 1) > RATE_TOLERANCE:
            raise CliError(f"{r.path}: sample rate {r.sample_rate_hz:.6g} Hz differs from {ref.path} "
                           f"({ref.sample_rate_hz:.6g} Hz); all recordings must share one sample rate")
    return recs


def _cleaned_copies(recs, paths, where: Path) -> list[str]:
    """Paths to pass on: the original file, or a cleaned copy in ``where`` when rows were dropped."""
    from ..io.recording import save_recording
    out = []
    for i, (r, p) in enumerate(zip(recs, paths)):
        if not r.dropped:
            out.append(p)
            continue
        d = where / f"{i:02d}"
        d.mkdir(parents=True, exist_ok=True)
        q = d / os.path.basename(p)
        save_recording(q, r, meta={**r.meta, "cleaned_from": os.path.abspath(p),
                                   "dropped_rows": len({o.line for o in r.dropped})})
        out.append(str(q))
    return out


def _publish(tmp: Path, out: Path) -> None:
    """Move the finished output from ``tmp`` to ``out`` (a rename when ``out`` does not exist)."""
    if not out.exists():
        os.rename(tmp, out)
        return
    if not out.is_dir():
        raise CliError(f"--out {out}: exists and is not a directory")
    for entry in tmp.iterdir():
        dest = out / entry.name
        if dest.is_dir() and not dest.is_symlink():
            shutil.rmtree(dest)
        os.replace(entry, dest)
    tmp.rmdir()


def _repoint(out: Path, tmp: Path) -> None:
    """Paths of the cleaned copies in the written files: from the temporary folder to ``out``."""
    old, new = json.dumps(str(tmp))[1:-1], json.dumps(str(out.resolve()))[1:-1]
    for name in ("diagnosis.json", "base_model.json", "refined_model.json", "report.html"):
        f = out / name
        if f.exists():
            text = f.read_text(encoding="utf-8")
            if old in text:
                f.write_text(text.replace(old, new), encoding="utf-8")


def run(args) -> int:
    from ..diagnose.run import diagnose
    if not (args.settle_s >= 0):
        raise CliError(f"--settle-s {args.settle_s:g}: must be >= 0")
    if args.max_terms < 0:
        raise CliError(f"--max-terms {args.max_terms}: must be >= 0")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out}: exists and is not a directory")
    paths = list(args.calibration) + list(args.recordings)
    recs = check_inputs(paths, args.settle_s, args.drop_outliers)
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
    except OSError as exc:
        raise CliError(f"--out {out}: cannot create: {exc.strerror or exc}") from None
    try:
        used = _cleaned_copies(recs, paths, tmp / "cleaned")
        ncal = len(args.calibration)
        doc = diagnose(used[:ncal], used[ncal:], str(tmp), settle_s=args.settle_s, max_terms=args.max_terms,
                       report=not args.no_report, png=args.png, log=lambda text: progress(args, text))
        _publish(tmp, out)
        if any(r.dropped for r in recs):
            _repoint(out, tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    # the documents name the files as given (not the cleaned copies' temporary paths)
    for f, p in zip(doc.get("drive_discontinuities", []), _given_paths(doc, paths, used)):
        f["file"] = p
    fit = doc["fit"]
    from ..diagnose.discriminate import inseparable_lines
    lines = [f"named: {', '.join(doc['named'])}"] + inseparable_lines(doc) + [
             f"NRMSE base {fit['base']['nrmse']:.4f} -> refined {fit['refined']['nrmse']:.4f} "
             f"(held-out {fit['heldout']['base_nrmse']:.4f} -> {fit['heldout']['refined_nrmse']:.4f})"]
    lines += discontinuity_lines(doc.get("drive_discontinuities", []))
    lines.append(f"written: {args.out}/diagnosis.json ({doc['time_s']:.1f} s)")
    emit(args, result_of(doc, out), lines)
    return 0


def _given_paths(doc, paths, used):
    """For each entry of ``drive_discontinuities``, the path the user gave for that file."""
    given = dict(zip(used, paths))
    return [given.get(f["file"], f["file"]) for f in doc.get("drive_discontinuities", [])]


def discontinuity_lines(dd: list) -> list[str]:
    """One line per file with drive discontinuities: how many, and the largest."""
    out = []
    for f in dd:
        j = max(f["jumps"], key=lambda j: abs(j["jump_v"]))
        out.append(f"drive discontinuities: {os.path.basename(f['file'])} ({f['role']}): {f['count']}, largest "
                   f"{j['u_before_v']:.2f} -> {j['u_after_v']:.2f} V at sample {j['sample']} (t {j['t_s']:.4f} s, "
                   f"{j['where']})")
    return out


def result_of(doc: dict, out: Path) -> dict:
    """The ``--json`` object: the verdict, the fit figures, the discontinuities and the files written."""
    return {"named": doc["named"], "inseparable": doc.get("inseparable", []), "fit": {k: doc["fit"][k] for k in ("base", "refined", "heldout")},
            "effects": [{"name": x["name"], "significant": x["significant"], "evidence": x["evidence"]}
                        for x in doc.get("effects", [])],
            "drive_discontinuities": doc.get("drive_discontinuities", []), "time_s": doc["time_s"],
            "diagnosis": str(out / "diagnosis.json"), "report": str(out / "report.html"),
            "base_model": str(out / "base_model.json"), "refined_model": str(out / "refined_model.json")}
