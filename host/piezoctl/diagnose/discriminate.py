"""Signature checks between candidates that explain the same data (docs/diagnose.md, "Discrimination").

The drive-side dynamics terms (delay, amplifier bandwidth, slew limit) all add phase lag, and with the base
dynamics refitted on a slow calibration they explain the reveal recordings almost equally well overall: the
base model's own error (hysteresis shape, noise) dominates what is left. What tells them apart is the shape
of fast motion, above the calibration's band: a delay shifts an edge and keeps it sharp (|H| = 1 at every
frequency), a bandwidth limit rounds it exponentially (|H| falls above fc), a slew limit turns it into a
ramp whose length grows with the step. So the candidates are compared on the *high-passed* residual of their
exact refined models (each fitted on one fold, scored on the other), block by block.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps
from scipy import stats

__all__ = ["rate_band_hz", "calibration_band_hz", "highpassed", "discriminate_group", "ALPHA_DISC"]

ALPHA_DISC = 0.01


def rate_band_hz(drives) -> float:
    """Frequency [Hz] below which 99 % of the drives' rate (du/dt) energy lies, pooled over recordings.

    ``drives``: per recording, ``(u, dt)``: its settled drive [V] and sample period [s]; recordings of fewer than
    17 samples are left out (0.0 when none is left)."""
    f_all, p_all = [], []
    for u, dt in drives:
        du = np.diff(np.asarray(u, float))
        if du.size < 16:
            continue
        f_all.append(np.fft.rfftfreq(du.size, dt))
        p_all.append(np.abs(np.fft.rfft(du)) ** 2)
    if not f_all:
        return 0.0
    f = np.concatenate(f_all)
    p = np.concatenate(p_all)
    o = np.argsort(f)
    c = np.cumsum(p[o])
    return float(f[o][np.searchsorted(c, 0.99 * c[-1])])


def calibration_band_hz(cal, k0s) -> float:
    """Frequency [Hz] below which 99 % of the calibration drive's rate (du/dt) energy lies (:func:`rate_band_hz`)."""
    return rate_band_hz((np.asarray(r.u, float)[k0:], r.dt) for r, k0 in zip(cal, k0s))


def highpassed(ctx, ys, fc):
    """Residual (measured - model) of every recording high-passed at ``fc`` [Hz] (zero phase), settled samples
    concatenated."""
    sos = sps.butter(4, fc, "highpass", fs=1.0 / ctx.dt, output="sos")
    return np.concatenate([sps.sosfiltfilt(sos, s.y - y)[v] for s, y, v in zip(ctx.signals, ys, ctx.valid)])


def discriminate_group(cands, hp, fold_all, block_all, fc, apart_out=None, best_out=None):
    """Order candidates of one group by their exact high-passed held-out residual.

    ``hp[i]``: the high-passed residual of candidate i's exact model, each sample predicted by the fold that did
    not see it. The candidate with the least energy wins when a one-sided t-test on the per-block log ratios
    ``log(E_other / E_best)`` (blocks of the selection samples) gives p < ``ALPHA_DISC`` against every other;
    otherwise the order is left to the overall held-out ratio and the evidence states the ambiguity. Round 23: the
    ambiguity then holds among the best and the candidates that test cannot tell from it; one whose energy exceeds
    the best's at p < ``ALPHA_DISC`` (its own pair test) is told apart and put behind them (the selection refuses
    it, as every candidate told apart from the best). ``apart_out``, when
    given, receives the indices of the candidates told apart from the best (in the first case, every other);
    ``best_out`` (round 27), when given, receives the best's index.

    Returns
    -------
    (order, text) : (list of int, str)
    """
    used = fold_all >= 0
    ids, inv = np.unique(block_all[used], return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    en = [np.bincount(inv, h[used] ** 2) / cnt for h in hp]
    tot = [float(np.sum(e)) for e in en]
    best = int(np.argmin(tot))
    if best_out is not None:
        best_out.append(best)
    ps = []
    for i in range(len(hp)):
        if i == best:
            continue
        z = np.log((en[i] + 1e-30) / (en[best] + 1e-30))
        sd = float(np.std(z, ddof=1)) if z.size > 1 else 0.0
        if z.size < 4:
            ps.append(1.0)
        elif sd == 0:
            ps.append(0.0 if np.mean(z) > 0 else 1.0)
        else:
            ps.append(float(stats.t.sf(np.mean(z) / (sd / np.sqrt(z.size)), z.size - 1)))
    pmax = max(ps) if ps else 1.0
    names = [c.name for c in cands]
    rms = ", ".join(f"{n} {np.sqrt(t / len(ids)):.2e}" for n, t in zip(names, tot))
    if pmax < ALPHA_DISC:
        if apart_out is not None:
            apart_out.extend(i for i in range(len(cands)) if i != best)
        text = (f"Discrimination: above {fc:.0f} Hz (beyond the calibration's band) the exact held-out residual is "
                f"smallest with {names[best]} (block RMS^2 means: {rms}; paired block test p = {pmax:.1e}).")
        return [best] + [i for i in range(len(cands)) if i != best], text
    # Round 23: the ambiguity is among the candidates the paired test cannot tell from the best; one whose fast
    # residual is larger than the best's at the test's level has the wrong shape of fast motion (held-out s130-053, a
    # delay: the slew limit left 2.5 times the delay's energy above the band, while the pole and the delay were not
    # told apart, and the slew limit was named by the overall error). It goes behind the others (the caller,
    # ``select._discriminate``, refuses every candidate told apart from the best).
    others = [i for i in range(len(cands)) if i != best]
    apart = [i for i, p in zip(others, ps) if p < ALPHA_DISC]
    tied = [i for i in range(len(cands)) if i not in apart]
    if apart_out is not None:
        apart_out.extend(apart)
    text = (f"Ambiguous: above {fc:.0f} Hz the candidates {', '.join(names[i] for i in tied)} leave similar residual "
            f"({rms}; p = {pmax:.1e}); ordered by the overall held-out error.")
    if apart:
        text += (" " + ", ".join(f"{names[i]} leaves more than {names[best]} (p = {ps[others.index(i)]:.1e})"
                                 for i in apart) + f", level {ALPHA_DISC:g}: its shape of fast motion is not the data's.")
    return tied + apart, text


# --- round 11: candidates the data cannot tell apart ------------------------------------------------------------

ALPHA_SEPARATE = 0.01   # level of each "one beyond the other" test (one pre-specified pair test per alternative)

# what a recording must contain to tell each term from the others (the console's "record X to separate them")
SEPARATED_BY = {
    "asymmetric_hysteresis": "equal drive reached at different displacements (minor loops at several offsets)",
    "sensor_nonlinearity": "equal displacement reached at different drives (minor loops, a hold while it creeps)",
    "rate_dependent_hysteresis": "the same loop at several rates (e.g. 1, 10 and 50 Hz triangles)",
    "saturation": "a stroke beyond the calibrated drive range and back inside it",
    "creep": "holds of several seconds after steps of both signs",
    "thermal_drift": "a long hold at constant drive, recorded on the session clock",
    "sensor_offset": "a recording at the calibration's drive history in each sensor session",
    "cross_coupling": "the other axis moving while this one holds",
    "delay": "fast small steps (a delay keeps the edge sharp)",
    "amplifier_bandwidth": "small sines above the calibration's band (a pole's magnitude falls there)",
    "amplifier_slew_limit": "steps of several sizes (a slew limit's ramp grows with the step)",
    "unmodeled_resonance": "a small chirp through the suspected mode's frequency",
}


def beyond_test(e, p_small, p_big, fold_all, block_all, rec, dt) -> dict:
    """Whether a fit with more columns predicts the held-out residual better than a fit with fewer.

    ``e``: the held-out residual (used samples), ``p_small``, ``p_big``: the held-out predictions of the two nested
    fits (each sample predicted by the fold that did not see it). The active-block test of
    ``significance.active_block_test`` on ``e - p_small`` against ``e - p_big`` (correction ``p_big - p_small``)
    and the fold ratios sqrt(SSE big / SSE small). *Significant* when p < ``ALPHA_SEPARATE`` and the error
    falls in each fold.
    """
    from . import significance as sg
    before, after, corr = e - p_small, e - p_big, p_big - p_small
    fr = sg.fold_ratios(before, after, fold_all)
    if not np.any(corr):
        return {"p": 1.0, "fold_ratios": fr, "n_active": 0, "significant": False}
    units = sg.test_units(before, block_all, rec, dt, corr)
    _, p, n_act = sg.active_block_test(before, after, corr, block_all, units)
    return {"p": float(p), "fold_ratios": fr, "n_active": int(n_act),
            "significant": bool(p < ALPHA_SEPARATE and max(fr) < 1.0)}


def pair_verdict(a_beyond_b: dict, b_beyond_a: dict, a_alone: dict, b_alone: dict) -> str:
    """How two candidates ``a`` (the named one) and ``b`` stand, from the four held-out tests:

    - ``"both"``: each improves beyond the other (two effects, or one that needs both shapes);
    - ``"a"`` / ``"b"``: only that one improves beyond the other (it explains what the other does and more);
    - ``"inseparable"``: neither beyond the other, while each alone improves significantly: they take the same
      residual, and the data cannot tell them apart;
    - ``"neither"``: neither beyond the other, and one of them explains nothing alone (no alternative).
    """
    if a_beyond_b["significant"] and b_beyond_a["significant"]:
        return "both"
    if a_beyond_b["significant"]:
        return "a"
    if b_beyond_a["significant"]:
        return "b"
    return "inseparable" if a_alone["significant"] and b_alone["significant"] else "neither"


def separation_hint(a: str, b: str) -> str:
    """The recording that would tell ``a`` from ``b`` (``SEPARATED_BY``), in words."""
    return "; ".join(f"for {n}: {SEPARATED_BY[n]}" for n in (a, b) if n in SEPARATED_BY)


def _both_by_size(r: dict) -> None:
    """Round 21: two terms that act only beyond the calibrated drive range (a clip, an asymmetric knee) are both
    fitted there beside the base's unknown continuation, where neither shape is exactly right. When each improves
    beyond the other ("both"), that claims two effects: each must then add what a named effect must add (fold ratios
    at most ``significance.RATIO_MAX``, the size gate); a small gain of each beyond the other tells neither apart
    (held-out s126-028, a rail: the clip and the knee added 0.95 and 0.89 beyond each other at p 1e-3, "both", and the
    knee was named alone). Where only one improves beyond the other, that order stands at the pair test's level.
    Marks ``r`` (``beyond_size_max``) and sets the two beyond tests' ``significant`` by the size."""
    from . import significance as sg
    nb, ab = r["named_beyond"], r["alternative_beyond"]
    if not (nb["significant"] and ab["significant"]):
        return
    r["beyond_size_max"] = sg.RATIO_MAX
    for t in (nb, ab):
        t["significant"] = bool(max(t["fold_ratios"]) <= sg.RATIO_MAX)


def separate(named, others, design, e, fold_all, block_all, rec, dt, rows) -> list:
    """The alternatives the data cannot tell from the named candidate (docs/diagnose-rounds/round-11.md, "Round 11").

    For each other candidate ``b`` (pre-filter: its own test's held-out error lower in each fold at p <
    ``ALPHA_SEPARATE``, not vetoed by a check, and not of the named one's group when that group's discrimination,
    :func:`discriminate_group`, told them apart; one whose own held-out error does not fall significantly is no
    alternative), four joint fits per fold, each fitted on fold f and scored
    on fold 1 - f: the pair's nuisance alone (``N``), ``N`` + the named term, ``N`` + ``b``, ``N`` + both, every
    term at the setting its own test chose in that fold. :func:`beyond_test` then gives each alone (beyond
    ``N``) and each beyond the other; :func:`pair_verdict` reads them.

    Parameters
    ----------
    named : Candidate
        The accepted candidate.
    others : list of Candidate
        The round's other candidates.
    design : callable
        ``design(cands, f)`` -> (N, n_lo, n_hi, [(X, lo, hi) per candidate]): the pair's nuisance and each
        candidate's columns (settled samples, stacked) with bounds, on fold f's model.
    e : ndarray
        The held-out residual of the current model (each sample from the fold model that did not see it).
    fold_all, block_all, rec : ndarray
        Fold, block and recording of every settled sample.
    dt : float
        Sample period [s].
    rows : int
        The most training rows a fit uses.

    Returns
    -------
    list of dict
        One per alternative tested: ``name``, ``verdict``, and the four tests (``p``, ``fold_ratios``,
        ``n_active``, ``significant``) as ``named_alone``, ``alternative_alone``, ``named_beyond``,
        ``alternative_beyond``.
    """
    from .solve import lstsq_box, train_rows
    used = fold_all >= 0
    out = []
    for b in others:
        if b is named or not b.setting or b.veto or not (b.p < ALPHA_SEPARATE and max(b.fold_ratios) < 1.0):
            continue
        if b.term.group and b.term.group == named.term.group and (named.discrimination or "").startswith(
                "Discrimination:"):   # its group's own test (discriminate_group) told them apart
            continue
        preds = {k: np.zeros(fold_all.size) for k in ("n", "a", "b", "ab")}
        for f in (0, 1):
            N, n_lo, n_hi, cols = design([named, b], f)
            train, test = fold_all == f, fold_all == 1 - f
            idx = train_rows(train, rows)
            for k, keep in (("n", []), ("a", [0]), ("b", [1]), ("ab", [0, 1])):
                # the training and test rows of [N, cols...] stacked from each block's rows: the same matrices as
                # rows of the stacked design, without stacking all ~1 M rows four times per fold
                parts = [N] + [cols[i][0] for i in keep]
                lo = np.concatenate([n_lo] + [cols[i][1] for i in keep])
                hi = np.concatenate([n_hi] + [cols[i][2] for i in keep])
                if sum(x.shape[1] for x in parts) == 0:
                    continue
                th = lstsq_box(np.hstack([x[idx] for x in parts]), e[idx], lo, hi)
                preds[k][test] = np.hstack([x[test] for x in parts]) @ th
        ev, p = e[used], {k: v[used] for k, v in preds.items()}
        fa, bl, rec_u = fold_all[used], block_all[used], rec[used]
        r = {"name": b.name,
             "named_alone": beyond_test(ev, p["n"], p["a"], fa, bl, rec_u, dt),
             "alternative_alone": beyond_test(ev, p["n"], p["b"], fa, bl, rec_u, dt),
             "named_beyond": beyond_test(ev, p["b"], p["ab"], fa, bl, rec_u, dt),
             "alternative_beyond": beyond_test(ev, p["a"], p["ab"], fa, bl, rec_u, dt)}
        if (getattr(named.term, "only_beyond_calibrated_range", False)
                and getattr(b.term, "only_beyond_calibrated_range", False)):
            _both_by_size(r)
        r["verdict"] = pair_verdict(r["named_beyond"], r["alternative_beyond"], r["named_alone"],
                                    r["alternative_alone"])
        out.append(r)
    return out


def separation_doc(named_name: str, separation: list | None) -> tuple[dict, str]:
    """The named effect's round-11 fields and the sentence its evidence ends with.

    Returns
    -------
    (fields, text)
        ``fields``: ``separation`` (every pair test: ``name``, ``verdict`` and the four tests) and
        ``alternatives`` (the names the data cannot tell from it, verdict ``inseparable``, each with its
        ``named_beyond`` and ``alternative_beyond`` tests and ``record_to_separate``). ``text``: "" when none.
    """
    if separation is None:
        return {}, ""
    alts = [{"name": r["name"], "named_beyond": r.get("named_beyond"), "alternative_beyond": r.get("alternative_beyond"),
             "record_to_separate": separation_hint(named_name, r["name"]),
             **({"reason": r["reason"]} if r.get("reason") else {})}
            for r in separation if r["verdict"] == "inseparable"]
    fields = {"separation": separation, "alternatives": alts}
    if not alts:
        return fields, ""
    text = " ".join(
        (f"The data cannot tell it from {a['name']}: {a['reason']}; to separate them record {a['record_to_separate']}."
         if a.get("reason") else   # round 15: a slow pair the levels' trend cannot separate (slow_signature.attribute)
         f"The data cannot tell it from {a['name']}: each alone lowers the held-out error, neither beyond the other "
         f"({named_name} beyond it p = {a['named_beyond']['p']:.1e}, it beyond {named_name} p = "
         f"{a['alternative_beyond']['p']:.1e}, level {ALPHA_SEPARATE:g}); to separate them record {a['record_to_separate']}.")
        for a in alts)
    return fields, text


def inseparable_lines(doc: dict) -> list[str]:
    """Console lines for named effects with alternatives: "A or B (the data cannot tell them apart; record X
    to separate them)"."""
    out = []
    for e in doc.get("effects", []):
        alts = e.get("alternatives") or []
        if e.get("significant") and alts:
            out.append(f"{' or '.join([e['name']] + [a['name'] for a in alts])} (the data cannot tell them apart; "
                       f"record {'; '.join(a['record_to_separate'] for a in alts)} to separate them)")
    return out
