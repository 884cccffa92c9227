"""Foreign diagnosis benchmark: ``tools/bench-diagnose --foreign`` (docs/foreign-stage.md).

Generates n cases of :mod:`piezoctl.foreign.cases` for a seed (a balanced mix: every
effect and nulls), runs ``piezoctl diagnose`` on each and prints one row per case, the
confusion table (truth x first named), the first-named score on effect cases, the nulls
that give ``none``, the held-out ratios and the seconds per case.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from ..foreign.cases import EFFECTS, case_plan, draw_case, write_case

__all__ = ["run_diagnose", "run_case", "ambiguous", "main"]


def run_diagnose(calibration: list, recordings: list, out_dir: str) -> dict:
    """The one call into the diagnosis (keep every dependency on its API here).

    Returns
    -------
    dict
        ``named`` (list of str, ``["none"]`` when nothing is named), ``ratio`` (held-out
        NRMSE of the refined model over the base's), ``base_nrmse``, ``refined_nrmse``,
        ``effect_ratios`` (name -> held-out ratio of each significant effect, where given),
        ``effect_ratios_acting`` (the same, above the edge a term acts above where the diagnosis gives it:
        ``improvement.exact_above``, round 19; beyond each recording's level where it gives that:
        ``improvement.exact_beyond_level``, round 22; else the same ratio), ``pair`` (the first
        named effect with the alternatives the data cannot tell it from, round 11; ``[]`` when none).
    """
    from ..diagnose.run import diagnose
    doc = diagnose(calibration, recordings, out_dir, report=False, log=lambda *a, **k: None)
    h = doc.get("fit", {}).get("heldout", {})
    base, refined = float(h.get("base_nrmse", float("nan"))), float(h.get("refined_nrmse", float("nan")))
    ratios, acting = {}, {}
    for e in doc.get("effects", []):
        imp = e.get("improvement") or {}
        if e.get("significant") and imp.get("nrmse_before"):
            ratios[e["name"]] = float(imp["nrmse_after"]) / float(imp["nrmse_before"])
            ab = (imp.get("exact_above")   # round 19: a mode's, above the edge it acts above
                  or imp.get("exact_beyond_level") or {})   # round 22: a coupling's, beyond each recording's level
            acting[e["name"]] = (float(ab["nrmse_after"]) / float(ab["nrmse_before"]) if ab.get("nrmse_before")
                                 else ratios[e["name"]])
    first = (doc.get("named") or ["none"])[0]
    pair = next((p for p in doc.get("inseparable", []) if p and p[0] == first), [])
    return {"named": list(doc.get("named") or ["none"]), "pair": list(pair), "base_nrmse": base,
            "refined_nrmse": refined,
            "ratio": refined / base if base > 0 else 1.0, "effect_ratios": ratios, "effect_ratios_acting": acting}


def run_case(seed: int, index: int, truth: tuple, scale: float, root: str) -> dict:
    """Generate, write and diagnose one case; returns its row."""
    t0 = time.perf_counter()
    case = draw_case(seed, index, truth, scale=scale)
    d = os.path.join(root, case.case_id)
    files = write_case(case, d)
    t1 = time.perf_counter()
    res = run_diagnose(files["calibration"], files["recordings"], os.path.join(d, "out"))
    t2 = time.perf_counter()
    data_s = sum(r.u.size for r in case.calibration + case.reveal) / 1e4
    return {"id": case.case_id, "law": case.stage.law.name, "truth": list(truth) or ["none"],
            "design": case.design, "gen_s": t1 - t0, "diag_s": t2 - t1, "data_s": data_s, **res}


def ambiguous(row: dict) -> bool:
    """A case whose first named effect came with alternatives the data cannot tell it from (``pair``) and whose
    truth is in that pair: "ambiguous, truth in pair", counted on its own line, not as first named correct."""
    return bool(row.get("pair")) and bool(set(row["truth"]) & set(row["pair"]))


def _print_summary(rows: list, multi: bool) -> None:
    labels = list(EFFECTS) + ["none"]
    print("\nconfusion (rows: truth, columns: first named)")
    used = [lab for lab in labels if any(r["named"][0] == lab or lab in r["truth"] for r in rows)]
    extra = sorted({r["named"][0] for r in rows} - set(used))
    used += extra
    print(" " * 26 + " ".join(f"{lab[:8]:>8s}" for lab in used))
    for t in used:
        sel = [r for r in rows if r["truth"][0] == t]
        if sel:
            print(f"{t:26s}" + " ".join(f"{sum(1 for r in sel if r['named'][0] == c):8d}" for c in used))
    eff = [r for r in rows if r["truth"] != ["none"]]
    nul = [r for r in rows if r["truth"] == ["none"]]
    if multi:
        both = sum(1 for r in eff if set(r["truth"]) <= set(r["named"]))
        first = sum(1 for r in eff if r["named"][0] in r["truth"])
        print(f"\ntwo-effect cases: both named {both}/{len(eff)}; first named is one of them {first}/{len(eff)}")
    else:
        amb = [r for r in eff if ambiguous(r)]
        ok = sum(1 for r in eff if r["named"][0] == r["truth"][0] and not ambiguous(r))
        print(f"\nfirst named correct (effect cases): {ok}/{len(eff)}")
        print(f"ambiguous, truth in pair (not counted as first named correct): {len(amb)}/{len(eff)}"
              + (" (" + ", ".join(f"{r['id']}: {' or '.join(r['pair'])}" for r in amb) + ")" if amb else ""))
    if nul:
        print(f"nulls 'none': {sum(1 for r in nul if r['named'] == ['none'])}/{len(nul)}")
    named = [r for r in rows if r["named"] != ["none"]]
    if named:
        rs = [r["ratio"] for r in named]
        print(f"held-out ratio (refined/base) of cases with a named effect: max {max(rs):.2f}, "
              f"<= 0.7 in {sum(1 for x in rs if x <= 0.7)}/{len(rs)}")
    er = [x for r in rows for x in r["effect_ratios"].values()]
    if er:
        print(f"held-out ratio of every named effect: max {max(er):.2f}, <= 0.7 in "
              f"{sum(1 for x in er if x <= 0.7)}/{len(er)}")
    ea = [x for r in rows for x in r.get("effect_ratios_acting", {}).values()]
    if ea:
        print(f"held-out ratio of every named effect where it acts (a mode: above its edge; a coupling: "
              f"beyond each recording's level): max {max(ea):.2f}, "
              f"<= 0.7 in {sum(1 for x in ea if x <= 0.7)}/{len(ea)}")
    ds = [r["diag_s"] for r in rows]
    gs = [r["gen_s"] for r in rows]
    print(f"seconds per case (diagnose): max {max(ds):.1f}, median {statistics.median(ds):.1f}; "
          f"generation: max {max(gs):.1f}, median {statistics.median(gs):.1f}; "
          f"data per case {min(r['data_s'] for r in rows):.0f}..{max(r['data_s'] for r in rows):.0f} s")


def main(argv=None) -> int:
    """Command line of ``tools/bench-diagnose --foreign``."""
    ap = argparse.ArgumentParser(prog="bench-diagnose --foreign")
    ap.add_argument("--foreign", action="store_true", help="(selects this benchmark)")
    ap.add_argument("--seed", type=int, default=0, help="case draw; development: 0..9, 101..142 (--multi 101..127); held out: >= 143 (--multi >= 128), run once per round (docs/foreign-stage.md)")
    ap.add_argument("--n", type=int, default=60, help="cases (n/5 nulls, the rest cycle through the effects)")
    ap.add_argument("--multi", action="store_true", help="two-effect cases instead")
    ap.add_argument("--scale", type=float, default=1.0, help="duration factor (1: 55 to 100 s of data per case)")
    ap.add_argument("--cases", default=None, help="comma list of case indices to run")
    ap.add_argument("--only", default=None, help="comma list of truths to run (effect names, 'none')")
    ap.add_argument("--keep", default=None, help="keep cases and outputs in this directory")
    ap.add_argument("--jobs", type=int, default=1, help="cases in parallel (default 1)")
    a = ap.parse_args(argv)
    root = a.keep or tempfile.mkdtemp(prefix="bench-foreign-")
    os.makedirs(root, exist_ok=True)
    plan = list(enumerate(case_plan(a.n, multi=a.multi)))
    if a.cases:
        keep = {int(x) for x in a.cases.split(",")}
        plan = [p for p in plan if p[0] in keep]
    if a.only:
        keep = set(a.only.split(","))
        plan = [p for p in plan if (set(p[1]) or {"none"}) & keep]
    if not plan:
        print("no case selected")
        return 2
    print(f"foreign benchmark: seed {a.seed}, {len(plan)} cases, scale {a.scale}, in {root}", flush=True)
    rows = []

    def show(r):
        named = ",".join(r["named"]) + (f" ({' or '.join(r['pair'])})" if r.get("pair") else "")
        print(f"{r['id']:42s} {r['law']:16s} truth {'+'.join(r['truth']):38s} named {named:40s} "
              f"ratio {r['ratio']:.2f} {r['diag_s']:6.1f} s (gen {r['gen_s']:.1f} s)", flush=True)

    if a.jobs <= 1:
        for i, truth in plan:
            rows.append(run_case(a.seed, i, truth, a.scale, root))
            show(rows[-1])
    else:
        with ProcessPoolExecutor(a.jobs) as ex:
            futs = [ex.submit(run_case, a.seed, i, truth, a.scale, root) for i, truth in plan]
            for f in futs:
                rows.append(f.result())
                show(rows[-1])
    _print_summary(rows, a.multi)
    print(f"cases in {root}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
