"""Forward selection of vocabulary terms with a cross-validated, nested significance test.

The recordings (after settling) are cut into ~1 s blocks; even blocks are fold A, odd
blocks fold B. Each candidate term (its grid setting and coefficients) is fitted on one
fold of the current model's residual and predicts the other, *nested*: jointly with free
gains on the current model's hysteresis channels (what a refit of the base could absorb
on the new data), against the model with those gains alone refitted on the same fold.
The significance rules are in ``significance.py``; every accepted term must also lower
the held-out error of the exact refined model in each fold. After each accepted term
every signal is re-derived from the refined model by exact simulation.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..dsp import blas_threads, filt
from ..ident import refined
from ..ident.terms import LATENCY_SAMPLES, Term, dynamics_corrections
from ..io.recording import session_start
from ..models.hysteresis import clear_output_cache, hysteresis_groups, initial_state_span
from . import significance as sg, static_map
from .misfit import _one_band_credited, above_per_recording, credited_ratio, ratios_above, ratios_where
from .discriminate import ALPHA_DISC, discriminate_group, highpassed, separate
from .slow_signature import (SIGNATURES, attribute, creep_coef_on_dwells, creep_model_on_dwells, creep_on_steps,
                             drift_coef_on_cycles, drift_on_cycles, drift_on_pair, signature_tests, step_holds,
                             step_phrase)
from .solve import lstsq_box as _lstsq_box, train_rows

__all__ = ["CHECKED_TERMS", "FURTHER_RATIO_MAX", "Signals", "Ctx", "Candidate", "make_masks", "make_signals",
           "residual", "select", "model_with", "simulate_refined", "hysteresis_nuisance", "slow_nuisance",
           "dynamics_nuisance", "initial_state_nuisance", "term_nuisance", "accepted_flexibility", "best_setting",
           "train_rows"]


# Rounds after the first (docs/diagnose-rounds/round-11.md, "Round 11: the second effect"). The first round's size gates (fold
# ratios and credited ratio <= significance.RATIO_MAX) keep a base misfit the misfit estimate underrates from being
# named; once an effect is in the model, a second one changes the held-out error by 1 to 30 % and cannot meet them.
# A term whose physics has its own test (its slow signature, beyond the other two and the base's misfit, at the
# search level ALPHA / 3; or the residual transfer's shape against unidentified dynamics, testable) is tested there
# with the size gates at FURTHER_RATIO_MAX instead: it must lower the held-out error in each fold and be credited
# with something beyond the base's misfit, at the round's level ALPHA / m (the remaining candidates: Holm's
# step-down), and its signature must hold. The slew limit's check is left out: its "absent below the limit" does not
# refuse a base misfit (round 10: null s101-004 passed it). Nor the offset's: its signature is a level per sensor
# session, and the drift's cubic is centred within each session, so the levels a drift leaves between sessions go to
# the offset's column by construction; below the gates a holding offset signature does not tell an offset from a
# drift (two-effect case s109-001 named its drift `sensor_offset` in round 2 with it). Terms without a
# discriminating check keep the first round's gates. Cross coupling has one since round 14 (its improvement must
# follow the other axis' motion beyond that axis' level per recording and the slow terms, _coupling_motion): what
# neither the base's hysteresis nor a drift can take, since both are functions of this axis' drive or the clock
# (round 18: after a creep, held-out s116-000 and s116-004 and development s115-000 refused a coupling at fold
# ratios 0.95, 0.87 and 0.82 against 0.8, p below the round's level).
FURTHER_RATIO_MAX = 1.0
CHECKED_TERMS = ("creep", "thermal_drift", "delay", "amplifier_bandwidth", "unmodeled_resonance", "cross_coupling")


@dataclasses.dataclass
class Signals:
    """One recording with the current model's signals (all arrays of the recording's length)."""

    name: str
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    u2: np.ndarray | None
    x2: np.ndarray | None
    temp: np.ndarray | None
    dt: float
    v: np.ndarray          # normalized drive after the model's drive terms
    h: np.ndarray          # H output [um]
    hyst: np.ndarray       # hysteretic part of H [um]
    yb: np.ndarray         # model output [um]
    ydyn: np.ndarray       # output before the offset and the output-stage terms [um]
    index: int = 0
    t_session: float | None = None   # the recording's start on the session clock [s] (metadata), when known


@dataclasses.dataclass
class Ctx:
    """The current model and everything the terms' regressors read (see ``piezoctl.ident.terms``)."""

    base: dict               # the current model's parameters (kind refined)
    signals: list            # Signals per recording
    valid: list              # bool masks (settled samples)
    fold: list               # 0/1 per sample (-1: not used)
    block: list              # global block id per sample
    names: list
    n_rec: int
    dt: float
    duration: float
    u2_ref: float
    y_center: float
    y_half: float
    u_lo: float
    u_hi: float
    u_mid_all: float
    u_half_all: float
    max_step: float
    peak_freqs: list
    y_span: float
    cal: list = dataclasses.field(default_factory=list)       # calibration recordings
    cal_h: list = dataclasses.field(default_factory=list)     # current H output on them [um]
    cal_k0: list = dataclasses.field(default_factory=list)    # settled start index per calibration recording
    refit_cache: dict = dataclasses.field(default_factory=dict)
    design_cache: dict = dataclasses.field(default_factory=dict)
    nuisance: np.ndarray | None = None   # hysteresis_nuisance() of this model, computed on first use
    dyn_nuisance: np.ndarray | None = None   # dynamics_nuisance() of this model, computed on first use
    init_nuisance: np.ndarray | None = None  # initial_state_nuisance() of this model, computed on first use
    bound_lag: bool = False   # round 21: the drive terms' dynamics corrections' lag bounded (_lag_beyond_latency)
    cal_u_lo: float = 0.0     # calibrated drive range [V] (settled calibration samples)
    cal_u_hi: float = 0.0
    drift_t0: float | None = None   # the session clock's reference for drift [s] (end of the calibration), when
    drift_span: float = 0.0         # every recording has session_time_s; the span of the recordings after it [s]
    offset_group: list | None = None  # per recording: its sensor-zero column (-1: the calibration's session, no
    #                                   offset of its own); None: one per recording (sessions unknown)
    offset_sessions: list | None = None  # the session label of each column, when sessions are known
    misfit: dict | None = None      # the base's error on held-out calibration histories (misfit.base_misfit)
    cal_band_hz: float | None = None  # the calibration's band (discriminate.calibration_band_hz) [Hz]; a term that
    #                                   acts above it is judged on the residual above it (round 16)
    dynamics_band_hz: float | None = None  # the band the base states its dynamics identified in [Hz] (round 18: the
    #                                        delay's shape check's alternative lies above it)
    mode_freqs: list | None = None  # where unmodeled_resonance is offered (round 12: the residual transfer's
    #                                 significant peak, signature.mode_frequencies); None: at peak_freqs
    accepted_flex: np.ndarray | None = None  # (n_settled, m): the accepted terms' own flexibility (their gains and
    #                                          their settings' grid neighbourhood, accepted_flexibility); a later
    #                                          candidate is nested against it (round 13)

    def offset_columns(self, s) -> np.ndarray:
        """The sensor-zero columns (n, m) of recording ``s``: a constant per sensor session other than the
        calibration's when every recording carries ``session``, else a constant per recording."""
        X = np.zeros((s.t.size, self.n_offset()))
        if self.offset_of(s.index) >= 0:
            X[:, self.offset_of(s.index)] = 1.0
        return X

    def n_offset(self) -> int:
        return self.n_rec if self.offset_group is None else len(self.offset_sessions or [])

    def offset_of(self, i: int) -> int:
        """Recording i's sensor-zero column (-1: none)."""
        return i if self.offset_group is None else int(self.offset_group[i])


@dataclasses.dataclass
class Candidate:
    """One term's evaluation in one selection round (per-fold lists: index f is the fit on fold f)."""

    term: Term
    ratio: float                     # linearized held-out NRMSE after / before (pooled)
    fold_ratios: list
    nrmse_before: float
    nrmse_after: float
    t: float
    p: float
    n_active: int
    p_max: float
    dbic: float
    n_eff: float
    significant: bool
    setting: list
    coef: list
    veto: str | None = None
    exact: list | None = None                 # per fold: params, sse_before, sse_after, n, ys
    exact_fold_ratios: list | None = None
    exact_before: float | None = None
    exact_after: float | None = None
    discrimination: str | None = None
    setting_all: object = None                # fitted on all settled samples (the refined model's term)
    coef_all: np.ndarray | None = None
    described: tuple | None = None            # (params with units, phrase)
    contrib: list | None = None               # per recording: the term's own contribution [um]
    worsened: tuple | None = None             # (recording, factor): one whose held-out error the term raised
    credited: float = 1.0                     # held-out ratio credited beyond the base's misfit (misfit.py)
    credited_bands: dict | None = None        # per band: the improvement and the misfit energy [um^2/sample]
    slow_signature: dict | None = None        # creep, drift, offset: its signature's unique contribution
    signature_check: dict | None = None       # the frequency-domain shape check (signature.py), drive-side terms
    ratio_max: float = sg.RATIO_MAX           # the size gate it was tested at (FURTHER_RATIO_MAX: after the first term,
    #                                           its signature must hold as well)
    selection_round: int = 1                  # the round it was evaluated in (1: on the base)
    separation: list | None = None            # accepted: the pair tests against the round's others (discriminate.separate)
    slow_alternative: dict | None = None      # sensor_offset: a drift its levels cannot exclude (slow_signature.attribute)
    delay_or_pole: dict | None = None         # round 20, delay and amplifier_bandwidth both significant: the gain test
    #                                           between them (signature.delay_or_pole)
    heldout: tuple | None = None              # (before, correction, fold, block, rec): signature.HELDOUT_CHECKED only
    exact_above: dict | None = None           # round 19: the exact check above the edge it was sized above
    exact_beyond_level: dict | None = None    # round 22: the exact check beyond each recording's level
    #                                           (``Term.ratio_beyond_level``)
    whole: dict | None = None                 # round 16, a term judged above the calibration's band: the edge [Hz]
    #                                           and its fold and credited ratios on the whole residual
    credited_only: bool = False               # round 18: it passed every gate but the credited ratio
    dwell_coef: list | None = None            # round 19, creep: per fold, its model sized on the dwells after the
    #                                           steps (slow_signature.creep_model_on_dwells)
    from_dwells: bool = False                 # round 19: that model passed the exact check (the one fitted on all
    #                                           blocks did not); the all-data model is sized on the dwells too
    from_cycles: bool = False                 # round 25, drift: its model sized on a repeated drive's cycles
    #                                           (slow_signature.drift_coef_on_cycles); so is the all-data model
    cycle_coef: list | None = None            # round 26, drift: per fold, (setting, coef) sized on those cycles
    #                                           for a significant candidate (slow_signature.drift_on_cycles)
    lag_apart_from: str | None = None         # round 27: the lag partner (LAG_PAIR) whose smaller fast residual
    #                                           refused it; lifted if that partner's own shape check fails
    lag_bounded: bool = False                 # round 21: evaluated with the corrections' lag bounded to the loop's
    #                                           latency (select._lag_beyond_latency)

    @property
    def below_gates(self) -> bool:
        """Significant only at FURTHER_RATIO_MAX: its fold or credited ratio exceeds the first round's gate."""
        return self.ratio_max > sg.RATIO_MAX and (max(self.fold_ratios) > sg.RATIO_MAX
                                                  or self.credited > sg.RATIO_MAX)

    @property
    def name(self) -> str:
        return self.term.name


def make_signals(params, recs, names) -> list:
    out = []
    off = float(params["hysteresis"].get("offset", 0.0))
    for i, (r, n) in enumerate(zip(recs, names)):
        ts = session_start(r)
        p = refined.simulate_parts(params, r.t, r.u, r.u2, ts)
        out.append(Signals(name=n, t=r.t, u=r.u, y=r.y, u2=r.u2, x2=r.x2, temp=r.temp, dt=r.dt, v=p["v"],
                           h=p["h"], hyst=p["hyst"], yb=p["y"], ydyn=p["y_dyn"] + off, index=i, t_session=ts))
    return out


FOLD_SHARE_MIN = 0.5   # round 20: the smaller fold's share of the excursion beyond the calibrated range (its sum of
#                        squared excursions over the larger fold's) below which make_masks shares those blocks out


def make_masks(sigs, settle_s, block_s, beyond=None):
    """(valid, fold, block) per recording: settled samples, fold 0/1 of alternate blocks, global block ids.

    Round 20: ``beyond`` (per recording, the drive's excursion beyond the calibrated drive range [V], 0 inside it).
    A term of the drive beyond the calibrated edge (a knee, a rail) can be fitted and tested only on those samples,
    and alternate blocks are blind to where the drive goes: a periodic drive whose excursions recur every second
    block put all of them in one fold (held-out s124-059: a triangle's every peak in fold 0; fold 1 trained on 1.9 V
    of excursion, and the true extra itself scored 0.07/1.00). When the alternate blocks give the smaller fold less
    than ``FOLD_SHARE_MIN`` of the larger's sum of squared excursions, the blocks that hold settled samples beyond
    the range go, in time order over all recordings, each to the fold whose such blocks so far hold the smaller sum;
    the other blocks alternate within each recording as before. Otherwise, and without such samples, the folds are
    the alternate blocks as before (a reshuffle of folds that already share the excursions changes nothing the test
    needs, and moves borderline cases at random: development s123-013, s119-013, s120-044)."""
    valid, fold, block, weights = [], [], [], []
    nb = 0
    for i, s in enumerate(sigs):
        n = s.t.size
        k0 = min(int(round(settle_s / s.dt)), n // 2)
        v = np.zeros(n, bool)
        v[k0:] = True
        m = n - k0
        nblk = int(np.clip(round(m * s.dt / block_s), 6, 40))
        b = np.full(n, -1)
        b[k0:] = np.minimum((np.arange(m) * nblk) // m, nblk - 1)
        f = np.where(b >= 0, b % 2, -1)
        x = np.zeros(m) if beyond is None else np.asarray(beyond[i], float)[k0:]
        weights.append((np.bincount(b[k0:], x ** 2, minlength=nblk), np.bincount(b[k0:], (x > 0).astype(float),
                                                                                   minlength=nblk) > 0, b))
        block.append(np.where(b >= 0, b + nb, -1))
        nb += nblk
        valid.append(v)
        fold.append(f)
    share = np.zeros(2)   # sum of squared excursions [V^2] per fold of the alternate blocks
    for w, _, _ in weights:
        share += [float(np.sum(w[0::2])), float(np.sum(w[1::2]))]
    if share.max() <= 0 or share.min() >= FOLD_SHARE_MIN * share.max():
        return valid, fold, block
    load = [0.0, 0.0]   # the same per fold of the blocks beyond, given out so far
    for i, (w, out, b) in enumerate(weights):
        fb = np.empty(w.size, int)
        fb[~out] = np.arange(int(np.sum(~out))) % 2
        for k in np.flatnonzero(out):
            fb[k] = int(load[1] < load[0])
            load[fb[k]] += float(w[k])
        fold[i] = np.where(b >= 0, fb[np.maximum(b, 0)], -1)
    return valid, fold, block


class _Design:
    """Stacked regressors of one term setting over all recordings (settled samples).

    Round 21: a design some of whose columns are bit for bit the same columns of ``ref`` (the term's first design
    in the context) keeps ``ref``'s columns and a copy of its own only. The rate term's five columns per setting
    are four the same for every setting (the constant widenings, the intercept) and one its own; its cached designs
    held 601 MiB of s0-017's 1960 MiB peak (docs/diagnose-rounds/round-20.md, "Round 20: speed and memory"). ``X`` of such a
    design stacks the columns on each request (the same C-ordered floats, not kept); a design that shares nothing
    keeps its stacked ``X`` as before (stacking a dozen columns of 1 M rows on every fit costs 0.1 s)."""

    def __init__(self, ctx, term, setting, ref=None):
        # ``ref``: a design or a list of them (round 26: the term's first design and its family's first, for a
        # term whose nuisance columns depend on the setting's family); each column is shared with the first of
        # them that holds it bit for bit
        refs = [r for r in (ref if isinstance(ref, (list, tuple)) else [ref]) if r is not None]
        self.setting = setting
        # each recording's settled rows copied once, straight into the stacked design (a masked copy per
        # recording and then np.vstack copied every design of about 1 M rows twice). Round 28: by ``np.take`` of
        # the settled indices with ``mode="clip"`` (they are in range, so nothing is clipped): ``np.compress``
        # (``take`` with the default ``mode="raise"``) buffers its ``out`` and copied every design twice, 6.5 of
        # s0-017's 117 s CPU
        n = sum(int(np.count_nonzero(v)) for v in ctx.valid)
        X, pos = None, 0
        for s, v in zip(ctx.signals, ctx.valid):
            R = np.asarray(term.regressors(ctx, s, setting), float)   # (samples, columns)
            if X is None:
                X = np.empty((n, R.shape[1]))
            i = np.flatnonzero(v)
            np.take(R, i, axis=0, out=X[pos:pos + i.size], mode="clip")
            pos += i.size
        self.n, self.k = X.shape
        same = {}   # column -> the reference design's same column
        for r in refs:
            if r.k != self.k:
                continue
            # equal to the bit (the int64 view: -0.0 and 0.0 differ, a NaN equals itself)
            # (round 22: every 1000th row first; a column differing there is not compared whole: 2.1 s of
            # held-out s125-023's 75 s were these comparisons, mostly of columns that differ from the first row)
            for j in range(self.k):
                if j not in same and np.array_equal(X[::1000, j].view(np.int64), r.col(j)[::1000].view(np.int64)) \
                        and np.array_equal(X[:, j].view(np.int64), r.col(j).view(np.int64)):
                    same[j] = r.col(j)
        if same:
            self._X = None
            self.cols = [same[j] if j in same else np.ascontiguousarray(X[:, j]) for j in range(self.k)]
            self.own_nbytes = (self.k - len(same)) * self.n * X.itemsize
        else:
            self._X, self.cols = X, None
            self.own_nbytes = X.nbytes

    def col(self, j) -> np.ndarray:
        """Column ``j`` (n_settled,) of the design (a view of the stacked design when it is kept)."""
        return self._X[:, j] if self._X is not None else self.cols[j]

    def rows(self, idx) -> np.ndarray:
        """``X[idx]`` (len(idx), k), C-ordered, the same floats, without stacking the other rows (round 26: a
        fit reads its training rows only; stacking a shared design whole for each of them was 11 of s0-017's
        114 s CPU)."""
        if self._X is not None:
            return self._X[idx]
        out = np.empty((len(idx), self.k))
        for j, c in enumerate(self.cols):
            out[:, j] = c[idx]
        return out

    def take(self, cols) -> np.ndarray:
        """``X[:, cols]`` (n_settled, len(cols)) without stacking the other columns: the same floats in the same
        layout (Fortran order, as numpy's indexing returns it; a fit's products are summed in another order on
        another layout, and the ratios moved by 1e-13)."""
        if self._X is not None:
            return self._X[:, cols]
        out = np.empty((self.n, len(cols)), order="F")
        for i, j in enumerate(cols):
            out[:, i] = self.cols[j]
        return out

    @property
    def X(self) -> np.ndarray:
        """The stacked design (n_settled, k), C-ordered."""
        if self._X is not None:
            return self._X
        X = np.empty((self.n, self.k))
        for j, c in enumerate(self.cols):
            X[:, j] = c
        return X


def _lstsq_bounded(X, y, lb):
    """Least squares with lower bounds ``lb`` (-inf: free) on unit-RMS columns."""
    return _lstsq_box(X, y, lb, np.inf)


_NUIS_GRAM: dict = {}   # the last nuisance's training products: {"last": (N, e, idx, N'N, N'e[idx])}


def _nuis_gram(N, e, idx):
    """(N' N, N' e[idx]) of the nuisance's training rows ``N`` (= the nuisance at rows ``idx``), kept for the
    next call: :func:`best_setting` fits every setting of a term against the same nuisance and residual, so
    these are computed once per term, fold and nuisance instead of once per setting. A hit needs the very same
    arrays (identity) and equal rows."""
    c = _NUIS_GRAM.get("last")
    if c is not None and c[0] is N and c[1] is e and np.array_equal(c[2], idx):
        return c[3], c[4]
    NN, Ne = N.T @ N, N.T @ e[idx]
    _NUIS_GRAM["last"] = (N, e, idx, NN, Ne)
    return NN, Ne


def _lstsq_gram(G, b, n):
    """Least squares from the normal equations ``G = X'X``, ``b = X'y`` of ``n`` rows, on unit-RMS columns (RMS
    from G's diagonal); rank deficiency is handled by the small solve's cutoff. The design is tall and narrow:
    a k x k solve instead of an SVD of the rows. Equal to round-off to the stacked version it replaced
    (``(X / sc)' (X / sc)`` formed from the rows; tests/host/test_diagnose_speed_round11.py)."""
    sc = np.sqrt(np.diag(G) / max(n, 1))
    sc[sc == 0] = 1.0
    th, *_ = np.linalg.lstsq(G / np.outer(sc, sc), b / sc, rcond=1e-12)
    return th / sc


def _predict(X, th, test, nuis=None):
    """The prediction on the test rows of the fit ``th`` of :func:`_fit_predict` (nuisance coefficients first)."""
    # the prediction on every row, then the test rows: the same floats as X[test] @ th (each row's dot product is
    # computed alike), without copying half the design's rows (about 1 M at full length) on every call
    if nuis is None:
        return (X @ th)[test]
    m = nuis[1].shape[1]
    return nuis[1] @ th[:m] + (X @ th[m:])[test]


def _fit_predict(X, e, train, test, rows, lb=None, nuis=None, predict=True):
    """Least squares of e on X over train rows (strided), coefficients >= ``lb`` when given; prediction on
    test rows (None without ``predict``: :func:`best_setting` predicts with its best setting only). ``nuis``: the
    nested test's nuisance as (train rows, test rows) of its columns, prepended (its coefficients first,
    unbounded), sliced once per fold by the caller.

    Unbounded fits are solved from their Gram matrix assembled by blocks: the nuisance's own block ``N'N`` is
    shared by all the settings of a term (:func:`_nuis_gram`), and no stacked copy ``[N, X]`` of the training
    rows is made."""
    idx = train_rows(train, rows)
    box = nuis is not None and len(nuis) > 2 and nuis[2] is not None
    y = e[idx]
    Xi = X.rows(idx) if isinstance(X, _Design) else X[idx]   # a design: its training rows only (round 26)
    if box:   # bounded nuisance columns (the initial state's gains): a box solve over all columns
        Xtr = np.hstack([nuis[0], Xi])
        lo = np.concatenate([nuis[2][0], np.full(Xi.shape[1], -np.inf) if lb is None else np.asarray(lb, float)])
        hi = np.concatenate([nuis[2][1], np.full(Xi.shape[1], np.inf)])
        th = _lstsq_box(Xtr, y, lo, hi)
        fit = Xtr @ th
    elif lb is not None:
        Xtr = Xi if nuis is None else np.hstack([nuis[0], Xi])
        if nuis is not None:
            lb = np.concatenate([np.full(nuis[0].shape[1], -np.inf), np.asarray(lb, float)])
        th = _lstsq_bounded(Xtr, y, lb)
        fit = Xtr @ th
    elif nuis is None:
        th = _lstsq_gram(Xi.T @ Xi, Xi.T @ y, idx.size)
        fit = Xi @ th
    else:
        N = nuis[0]
        NN, Ny = _nuis_gram(N, e, idx)
        NX = N.T @ Xi
        G = np.block([[NN, NX], [NX.T, Xi.T @ Xi]])
        th = _lstsq_gram(G, np.concatenate([Ny, Xi.T @ y]), idx.size)
        m = N.shape[1]
        fit = N @ th[:m] + Xi @ th[m:]
    sse_tr = float(np.sum((y - fit) ** 2)) * (np.sum(train) / max(idx.size, 1))
    return th, (_predict(X.X if isinstance(X, _Design) else X, th, test, nuis) if predict else None), sse_tr


def _design(ctx, term, st):
    key = (term.name, repr(st))
    if key not in ctx.design_cache:
        mine = [d for k, d in ctx.design_cache.items() if k[0] == term.name]
        refs = mine[:1]
        if getattr(term, "setting_nuisance", False):   # round 26: and its family's first design (the rate
            # term's narrowing settings share their constant shift columns, which the first, widening, design
            # holds as zeros: 2 of 3 own columns of each narrowing design, 267 MiB of s0-017's peak)
            refs += [d for d in mine if term.family(d.setting) == term.family(st)][:1]
        ctx.design_cache[key] = _Design(ctx, term, st, refs)
    return ctx.design_cache[key]


def _keep_designs(ctx, term, settings):
    """Drops from ``ctx.design_cache`` every design but those of ``term`` at ``settings`` (a dropped one is
    recomputed, to the same floats, if asked for again)."""
    keep = {(term.name, repr(st)) for st in settings}
    for key in [k for k in ctx.design_cache if k not in keep]:
        del ctx.design_cache[key]


def best_setting(ctx, term, e, train, test, rows, nuis=None):
    """(setting, design, sse on train, prediction on test, coefficients) with the least training error over the
    term's grid, then over its finer settings around the best one (``Term.refine``, twice). With ``nuis``
    (see :func:`_fit_predict`) the nuisance is fitted jointly and its coefficients are dropped from the result."""
    settings = term.settings(ctx)
    lb = term.lower(ctx)
    best = None
    # round 25: a term whose nuisance columns depend on the setting's family (``Term.setting_nuisance``) ranks its
    # settings by their training error less that of their own family's nuisance alone: the family with more
    # nuisance columns would otherwise win on what those columns take
    ref: dict = {}

    def score(st, d, sse):
        if not getattr(term, "setting_nuisance", False):
            return sse
        f = term.family(st)
        if f not in ref:
            own = term.nuisance_columns(ctx, d.k)
            ref[f] = _fit_predict(d.take(own), e, train, test, rows, nuis=nuis, predict=False)[2] if own else 0.0
        return sse - ref[f]
    level = {}   # refinement level at which each tried setting was proposed (grid: 0)
    new_level = 0
    for _ in range(3):
        for st in settings:
            if repr(st) in level:
                continue
            level[repr(st)] = new_level
            d = _design(ctx, term, st)
            # round 22: the test rows are predicted with the best setting only (below), not with every setting
            # (the whole design times the coefficients and the nuisance's test rows: about half of each fit)
            th, _, sse = _fit_predict(d, e, train, test, rows, lb, nuis, predict=False)
            sc = score(st, d, sse)
            if best is None or sc < best_score:
                best, best_score = (st, d, sse, th), sc
        new_level = level[repr(best[0])] + 1
        settings = term.refine(ctx, best[0], new_level) if new_level <= 2 else []
        if not settings:
            break
    st, d, sse, th = best
    pa = _predict(d.X, th, test, nuis)
    return st, d, sse, pa, (th if nuis is None else th[nuis[0].shape[1]:])


def hysteresis_nuisance(ctx):
    """The nested tests' nuisance (n_settled, m): the current model's hysteresis groups through its dynamics
    (free gains on them refit the base's own flexibility on the new data: the reversible curve's gain, the loop
    width, the Bouc-Wen column; see ``models.hysteresis.hysteresis_groups``), centred on the calibration, stacked over the settled samples; cached on the
    context. No constant: an offset
    between the calibration's session and the recordings' is a finding (sensor_offset), not the base's misfit
    (with a constant here, the valve's 1 um session offset was absorbed and the verdict was `none`)."""
    if ctx.nuisance is None:
        hp = ctx.base["hysteresis"]
        b, a = ctx.base["dynamics"]["b"], ctx.base["dynamics"]["a"]
        # each channel centred on its mean over the settled calibration: a gain on the reversible curve (which
        # spans the stroke) must not stand in for an offset either
        cal = [hysteresis_groups(hp, (r.u - float(ctx.base["u_mid"])) / float(ctx.base["u_half"]))[k0:]
               for r, k0 in zip(ctx.cal, ctx.cal_k0)]
        mean = np.concatenate(cal).mean(axis=0) if cal else 0.0
        ctx.nuisance = np.vstack([filt(b, a, hysteresis_groups(hp, s.v) - mean)[v]
                                  for s, v in zip(ctx.signals, ctx.valid)])
    return ctx.nuisance


def dynamics_nuisance(ctx):
    """The drive-side and resonance terms' extra nuisance (n_settled, 2): the first and second time derivatives
    of the current model's dynamic output, i.e. free low-order corrections ``c1 s + c2 s^2`` of its dynamics G
    (unit static gain kept) refitted on the new data. Above the calibration's band G was not identified: a
    stage's own latency and the phase of its modes there look like a delay of a sample or two, and a
    drive-side term is credited only with what such a refit of G cannot absorb (round 5 named `delay` on
    nulls whose fast reveal showed the stage's one-sample latency). Cached on the context. Round 20: the
    corrections act in the whole band; only above the base's dynamics band (round 19's variant) they left a true
    delay's in-band lag to the pole as well, and on null s121-005 the stage's own in-band lag was named
    `amplifier_bandwidth` x0.14 (docs/diagnose-rounds/round-19.md "Round 19: delay", "Round 20: delay and bandwidth"). Round 21:
    when no drive-side term passes against them, those terms are tested again with the lag ``c1`` bounded to the
    loop's latency (:func:`_lag_beyond_latency`): free, it took a true delay's first-order lag in the whole band
    ("Round 21: delay")."""
    return dynamics_corrections(ctx)


def initial_state_nuisance(ctx):
    """The level-like terms' extra nuisance (n_settled, n_rec): per recording, the current model's output with
    the history coming down from the top of the calibrated range minus coming up from its bottom, through the
    dynamics. A recording starts in a hysteresis state nobody recorded; for a Preisach density of one sign every
    state's output lies between these two, so the true output is the model's plus ``g`` times this difference
    with ``|g| <= 1`` (the bounds of :func:`initial_state_bounds`); the difference dies out once the drive has
    visited both ends. Without it a null whose recording never wiped its initial state named a sensor offset
    (round 6, held-out null s102-004: one recording 0.21 um off). Cached on the context."""
    if ctx.init_nuisance is None:
        hp = ctx.base["hysteresis"]
        b, a = ctx.base["dynamics"]["b"], ctx.base["dynamics"]["a"]
        mid, half = float(ctx.base["u_mid"]), float(ctx.base["u_half"])
        v_lo, v_hi = (ctx.cal_u_lo - mid) / half, (ctx.cal_u_hi - mid) / half
        cols = []
        for s in ctx.signals:
            d = np.zeros((s.v.size, ctx.n_rec))
            d[:, s.index] = filt(b, a, initial_state_span(hp, s.v, v_lo, v_hi))
            cols.append(d)
        ctx.init_nuisance = np.vstack([c[v] for c, v in zip(cols, ctx.valid)])
    return ctx.init_nuisance


def slow_nuisance(ctx):
    """The nuisance of the slow signatures' joint test (``slow_signature.py``): the hysteresis groups (free) and
    the initial state's gains (within [-1, 1]), as (columns, lower bounds, upper bounds)."""
    Nh, Ni = hysteresis_nuisance(ctx), initial_state_nuisance(ctx)
    lo = np.concatenate([np.full(Nh.shape[1], -np.inf), np.full(Ni.shape[1], -1.0)])
    return np.hstack([Nh, Ni]), lo, -lo


def term_nuisance(ctx, term, dynamics: bool = True, initial: bool = True, accepted: bool = True,
                  own_test: bool = True):
    """The nested test's nuisance columns for ``term`` (None: not nested); ``dynamics=False`` leaves out the
    dynamics corrections (the term's setting for the model is chosen without them: they would take part of a
    delay or a pole and bias the setting); ``initial=False`` leaves out the initial-state columns (the same for
    the coefficients: the refined model has no initial state per recording, so a level they took would be
    missing from its term); ``accepted=False`` leaves out the accepted terms' flexibility (``ctx.accepted_flex``,
    for the same reason); ``own_test=False`` leaves out the term's own test nuisance (``Term.test_nuisance``). The
    initial-state columns, when taken, come last (bounds: :func:`nuisance_bounds`)."""
    parts = _nuisance_parts(ctx, term, dynamics, initial, accepted, own_test)
    return np.hstack(parts) if parts else None


def _nuisance_parts(ctx, term, dynamics=True, initial=True, accepted=True, own_test=True) -> list:
    """The blocks of columns :func:`term_nuisance` stacks, in its order (each cached by its own function)."""
    parts = []
    if term.nested:
        parts.append(hysteresis_nuisance(ctx))
    if term.nested_dynamics and dynamics:
        parts.append(dynamics_nuisance(ctx))
    if accepted and ctx.accepted_flex is not None:
        parts.append(ctx.accepted_flex)
    test = getattr(term, "test_nuisance", None) if own_test else None   # a term's own test-only nuisance (round 17:
    if test is not None:                                                 # the rate term's; round 20: the curve's)
        x = test(ctx)
        if x is not None and x.shape[1]:
            parts.append(x)
    if term.initial_state and initial:
        parts.append(initial_state_nuisance(ctx))
    return parts


def _neighbours(ctx, term, st) -> list:
    """The settings next to ``st`` on ``term``'s grid: its first refinement around ``st`` (half a grid step either
    side: saturation, the geometric drive-side grids), else the grid's settings before and after ``st``; none for
    a setting None (a term without one, or the asymmetric term's whole-stroke form)."""
    if st is None:
        return []
    near = list(term.refine(ctx, st, 1))
    if near:
        return near
    grid = term.settings(ctx)
    keys = [repr(x) for x in grid]
    if repr(st) not in keys:
        return []
    i = keys.index(repr(st))
    return [grid[j] for j in (i - 1, i + 1) if 0 <= j < len(grid)]


def accepted_flexibility(ctx, term, st) -> np.ndarray:
    """An accepted term's own flexibility (n_settled, m) on the model *without* it (``ctx``): its own regressor
    columns at its setting ``st`` (a free gain on what it does) and the change of those columns to each grid
    neighbour of ``st`` (:func:`_neighbours`: the first-order change of its setting). A later candidate is nested
    against these columns as every candidate is against the base's hysteresis channels: what a refit of the
    first term's gain and setting on the new data absorbs - a clip level half a grid step off, a slew limit's
    residual ramps, a rate reference between two grid points - is not credited to a second effect (round 13:
    an even polynomial of the drive after a saturation, a rate term after a slew limit). Columns that are zero
    on every settled sample (a neighbour the data never reach) are dropped."""
    def own(x):
        d = _design(ctx, term, x).X
        keep = [j for j in range(d.shape[1]) if j not in term.nuisance_columns(ctx, d.shape[1])]
        return d[:, keep]
    x0 = own(st)
    cols = [x0] + [own(x) - x0 for x in _neighbours(ctx, term, st)]
    ctx.design_cache.clear()
    X = np.hstack(cols)
    return X[:, np.any(X != 0.0, axis=0)]


def nuisance_bounds(ctx, term, N, initial: bool = True, dynamics: bool = True):
    """(lo, hi) of the nuisance columns ``N`` of ``term`` (None: all free): the initial state's gains within
    [-1, 1]; round 21: while ``ctx.bound_lag`` is set (:func:`_lag_beyond_latency`), the dynamics corrections' lag
    ``c1`` (the first column of :func:`dynamics_nuisance`, in samples) within the term's ``dynamics_lag_bound`` when
    it states one (the drive-side terms: the loop's own latency, ``ident.terms._DriveTerm``); the other columns free.
    ``dynamics``: the dynamics corrections are among the columns (:func:`term_nuisance`)."""
    if N is None:
        return None
    lag = (getattr(term, "dynamics_lag_bound", None) if (term.nested_dynamics and dynamics and
                                                          getattr(ctx, "bound_lag", False)) else None)
    box = term.initial_state and initial
    if lag is None and not box:
        return None
    m = N.shape[1]
    lo, hi = np.full(m, -np.inf), np.full(m, np.inf)
    if lag is not None:   # the columns' order is term_nuisance's: the hysteresis channels, then c1, c2
        j = hysteresis_nuisance(ctx).shape[1] if term.nested else 0
        lo[j], hi[j] = -float(lag), float(lag)
    if box:
        lo[m - ctx.n_rec:], hi[m - ctx.n_rec:] = -1.0, 1.0
    return lo, hi


def _nuis(ctx, term, train, test, rows, dynamics: bool = True, initial: bool = True, accepted: bool = True):
    """The nuisance as passed to :func:`_fit_predict`: (train rows, test rows, bounds), or None.

    Round 21: each block's rows are taken and then stacked (the same floats as the rows of
    :func:`term_nuisance`'s stacked columns): the whole stacked nuisance (n_settled x tens of columns) was made
    for every term and fold only to be sliced, and was s0-017's peak once the rate designs shared their columns."""
    parts = _nuisance_parts(ctx, term, dynamics, initial, accepted)
    if not parts:
        return None
    idx = train_rows(train, rows)
    Ntr = np.hstack([p[idx] for p in parts])
    return (Ntr, np.hstack([p[test] for p in parts]), nuisance_bounds(ctx, term, Ntr, initial, dynamics))


BEYOND_GUARD_S = 0.1   # [s] after the drive comes back into the calibrated range (run.OUT_GUARD_S)


def beyond_calibrated_mask(ctx) -> np.ndarray:
    """Settled samples (concatenated) where the drive is beyond the calibrated drive range
    ``[ctx.cal_u_lo, ctx.cal_u_hi]`` or left it less than ``BEYOND_GUARD_S`` before: where a term of the drive
    beyond the calibrated edge (``Term.acts_beyond_calibration``) can act, a backlash holding it while the drive
    turns back. All False when no calibrated range is known."""
    out = []
    for s, v in zip(ctx.signals, ctx.valid):
        b = np.zeros(s.u.size, bool)
        if ctx.cal_u_hi > ctx.cal_u_lo:
            b = (s.u > ctx.cal_u_hi) | (s.u < ctx.cal_u_lo)
            g = max(1, int(round(BEYOND_GUARD_S / s.dt)))
            c = np.cumsum(b.astype(int))
            prev = np.concatenate([np.zeros(g, int), c[:-g]]) if c.size > g else np.zeros(c.size, int)
            b = (c - prev) > 0
        out.append(b[v])
    return np.concatenate(out)


def inside_calibrated_veto(ctx, e_before, correction, fold, within) -> str | None:
    """Round 25: why a map of the reading (``Term.sized_inside_calibration``: the sensor's curve) is not credited
    where the recordings leave the calibrated drive range, or None.

    A sensor's curve is a static map of the displacement read, the same on every recording and inside the
    calibrated range as beyond it. Beyond the calibrated edge the base goes on as a straight line, and a missing
    curvature there is also what a term of the drive beyond the edge takes (an asymmetric loop past a knee, a
    rail): the data cannot tell them apart there ("Known limits"). Inside the range the two differ: an asymmetry
    or a rail beyond the edge leaves the in-range samples as the calibration left them, a curve that changed since
    the calibration bends them too. So where the recordings go beyond the edge (on a side, by more than the knee
    grid's step: ``beyond_calibrated_sides``, the asymmetry's and saturation's own condition), the curve must pass
    its size gate on the samples inside the range as well (held-out s133-013, an asymmetry past a knee 3.4 V
    beyond the edge on a Bouc-Wen stage, was named ``sensor_nonlinearity``).

    Parameters
    ----------
    ctx : the fold-0 context (its signals, valid masks and calibrated range).
    e_before, correction : ndarray
        The nested residual before the term and its held-out predicted correction [um], used samples.
    fold : ndarray of int
        Fold of each used sample.
    within : callable
        The size gate on one fold ratio (``_evaluate``'s).

    Returns
    -------
    str or None
        The veto's reason, with the in-range fold ratios; None where the recordings stay inside the range or the
        curve passes there.
    """
    from ..ident.terms import beyond_calibrated_sides
    if not beyond_calibrated_sides(ctx, INSIDE_STEP):
        return None
    inside = ~beyond_calibrated_mask(ctx)
    fr, _ = ratios_where(e_before, correction, fold, inside, None) if np.any(inside) else (None, None)
    if fr is not None and all(within(x) for x in fr):
        return None
    shown = "no sample" if fr is None else "fold ratios " + "/".join(f"{x:.2f}" for x in fr)
    return (f"its held-out improvement lies beyond the calibrated drive range: on the samples inside it ({shown}) "
            f"it does not pass the size gate, and a sensor's curve reads the same displacement there; beyond the "
            f"edge a missing curvature is the base's straight continuation or a term of the drive there "
            f"(asymmetric hysteresis, saturation)")


INSIDE_STEP = 0.025   # [fraction of the drive span] beyond the calibrated edge: the asymmetry's and saturation's grid
#                       step (their ``STEP``), the same reach that lets them be offered


def residual(ctx):
    return np.concatenate([(s.y - s.yb)[v] for s, v in zip(ctx.signals, ctx.valid)])


UNIDENTIFIED_GAIN = 100.0   # a held-out prediction this many times the residual's RMS: the fit was not determined


def _unidentified(e, e_before, pred) -> str | None:
    """Why a fold's nested fit (nuisance refit and term) is not determined by its training rows, or None.

    A column that barely moves on the training rows but moves on the held-out ones (a play of one recording that
    turns only inside a held-out block) gets an unbounded coefficient from the normal equations, and its held-out
    prediction is then orders of magnitude beyond the residual it should explain: no refit of a model's own
    flexibility nor a concealed effect predicts a held-out residual with ``UNIDENTIFIED_GAIN`` times its RMS.
    Held-out s120-031 (round 17): the rate term's per-recording groups predicted beyond 1e150 um and overflowed the block
    test; the guard turns that into a refusal of the term, with this reason, instead of a crash."""
    if not e.size:
        return None
    scale = float(np.sqrt(np.mean(e ** 2)))
    with np.errstate(over="ignore", invalid="ignore"):
        big = max(float(np.sqrt(np.mean(e_before ** 2))), float(np.sqrt(np.mean(pred ** 2))))
    if np.isfinite(big) and big <= UNIDENTIFIED_GAIN * max(scale, 1e-300):
        return None
    return (f"its nested fit is not determined by the training rows: a held-out prediction of {big:.3g} um RMS "
            f"against a residual of {scale:.3g} um RMS (more than {UNIDENTIFIED_GAIN:g}x)")


def _evaluate(ctxs, term, es, fold_all, block_all, rows, p_max, ratio_max=sg.RATIO_MAX,
              beside_drive: bool = False) -> Candidate:
    """Cross-validated evaluation of ``term`` on top of the current model.

    ``ctxs[f]``, ``es[f]``: the model (terms accepted so far, fitted on fold f only) and its residual; the
    candidate is fitted on fold f of that residual and predicts fold 1 - f. ``ratio_max``: the size gate of the
    fold ratios and the credited ratio (``significance.RATIO_MAX``; ``FURTHER_RATIO_MAX`` after the first term for
    a term in ``CHECKED_TERMS``, strictly below it then). ``beside_drive``: a drive-side term (group
    ``drive_dynamics``) is in the model; a term sized above an edge is then block-tested on the whole band only
    (:func:`_linearized_gates`, round 24).
    """
    e_before = np.zeros(fold_all.size)
    pred_after = np.zeros(fold_all.size)
    chosen, fold_ratios, best_st = [], [], []
    unidentified = None
    k = 1
    for f in (0, 1):
        ctx, e = ctxs[f], es[f]
        settings = term.settings(ctx)
        d0 = _design(ctx, term, settings[0])
        own = term.nuisance_columns(ctx, d0.k)
        k = max(_design(ctx, term, st).k for st in settings) - len(own) + (1 if len(settings) > 1 else 0)
        train, test = fold_all == f, fold_all == 1 - f
        e_before[test] = e[test]
        N = _nuis(ctx, term, train, test, rows)   # nested against a refit of the model's own flexibility here
        if own or N is not None:  # "before" is the model with the nuisance columns alone refitted here
            Xn = d0.take(own) if own else np.zeros((e.size, 0))
            _, pn, _ = _fit_predict(Xn, e, train, test, rows, nuis=N)
            e_before[test] = e[test] - pn
        best = best_setting(ctx, term, e, train, test, rows, N)
        if getattr(term, "setting_nuisance", False) and (own or N is not None):   # round 25: "before" with the
            # chosen setting's own family's nuisance
            own_b = term.nuisance_columns(ctx, best[1].k)
            Xn = best[1].take(own_b) if own_b else np.zeros((e.size, 0))
            _, pn, _ = _fit_predict(Xn, e, train, test, rows, nuis=N)
            e_before[test] = e[test] - pn
        best_st.append(best[0])
        pred_after[test] = best[3] - (e[test] - e_before[test])
        why = _unidentified(e[test], e_before[test], pred_after[test])
        if why:   # the nested refit is not determined by this fold's training rows: no test, no credit
            unidentified = unidentified or why
            e_before[test], pred_after[test] = e[test], 0.0
        if term.fit_model_alone(ctx):   # round 17: the model's coefficients fitted with its own columns alone
            chosen.append(best_setting(ctx, term, e, train, test, rows))
        elif term.nested_dynamics or term.initial_state or ctx.accepted_flex is not None:   # the model's setting and
            Nm = _nuis(ctx, term, train, test, rows, dynamics=False, initial=False,    # coefficients: without the
                       accepted=False)                                                # columns it will not have
            chosen.append(best_setting(ctx, term, e, train, test, rows, Nm))
        else:
            chosen.append(best)
        rb = float(np.sqrt(np.mean(e_before[test] ** 2)))
        ra = float(np.sqrt(np.mean((e[test] - best[3]) ** 2)))
        fold_ratios.append(ra / rb if rb > 0 else 1.0)
        # round 20: after the first round fold 1 has its own context; of fold 0's designs only its chosen settings
        # are asked for again (_beside_unlimited), the others would stay beside fold 1's until the end
        if f == 0 and ctxs[1] is not ctx:
            _keep_designs(ctx, term, (best[0], chosen[-1][0]))
    span = ctxs[0].y_span
    used = fold_all >= 0
    rb_res = e_before[used]
    ra_res = (e_before - pred_after)[used]
    nb = float(np.sqrt(np.mean(rb_res ** 2)) / span)
    na = float(np.sqrt(np.mean(ra_res ** 2)) / span)
    rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(ctxs[0].valid)])[used]
    units = sg.test_units(rb_res, block_all[used], rec, ctxs[0].dt, pred_after[used])
    t, p, n_act = sg.active_block_test(rb_res, ra_res, pred_after[used], block_all[used], units)
    neff = sg.effective_n(rb_res)
    dbic = sg.bic_delta(float(np.sum(rb_res ** 2)), float(np.sum(ra_res ** 2)), neff, k)
    within = (lambda x: x <= ratio_max) if ratio_max < FURTHER_RATIO_MAX else (lambda x: x < ratio_max)
    cr, bands = credited_ratio(rb_res, pred_after[used], rec, ctxs[0].dt, ctxs[0].misfit)
    whole = None
    edge = term.acts_above_hz(ctxs[0], best_st)   # round 17: the mode's own band when above the calibration's
    if edge:   # round 16: sized on the band where it acts (misfit.ratios_above), not beside the base's slow misfit
        fr_above, cr_above = ratios_above(rb_res, pred_after[used], fold_all[used], rec, ctxs[0].dt, edge,
                                          ctxs[0].misfit)
        if fr_above is not None:
            whole = {"above_hz": float(edge), "fold_ratios": list(fold_ratios), "credited_ratio": cr}
            fold_ratios, cr = fr_above, cr_above
            # round 21: where its correction lies (the mode's veto acts_below_edge); round 23: the block test and
            # BIC above the edge, read by _linearized_gates beside the whole band's
            whole.update(_above_edge_evidence(rb_res, pred_after[used], block_all[used], rec, ctxs[0].dt, edge, k))
    if term.acts_beyond_calibration and whole is None and all(st is not None for st in best_st):
        # round 17: a knee setting in both folds acts only beyond the edge: sized on the samples where it can act
        w = beyond_calibrated_mask(ctxs[0])[used]
        fr_w, cr_w = ratios_where(rb_res, pred_after[used], fold_all[used], w, ctxs[0].misfit) if np.any(w) else (
            None, None)
        if fr_w is not None:
            whole = {"beyond_calibrated_range": True, "fold_ratios": list(fold_ratios), "credited_ratio": cr}
            fold_ratios, cr = fr_w, cr_w
    significant = _linearized_gates(fold_ratios, p, dbic, whole, p_max, within, ratio_max < FURTHER_RATIO_MAX,
                                    above_p=not beside_drive)
    veto = None
    # round 13: data that cannot credit it; round 15: vetoed whether or not it passed, so that it is no pair's
    # alternative either (held-out s114-026: an in-range clip below the round's level, reported as the sensor
    # curve's inseparable alternative)
    refusal = term.refuses(ctxs[0]) or unidentified
    if refusal:
        significant, veto = False, refusal
    if significant:   # round 15: a fit whose size is not the term's physics (the rate term's widening)
        veto = next((w for w in (term.implausible(ctxs[0], c[0], c[4]) for c in chosen) if w), None)
        significant = veto is None
    if significant and whole is not None and "share_above" in whole:   # round 21: where it acts, not below
        veto = term.acts_below_edge(whole["share_above"], whole["above_hz"])
        significant = veto is None
    credited_only = bool(significant and not within(cr))
    if significant and not within(cr):
        significant = False
        veto = (f"its held-out improvement lies within what the base's error on calibration histories it did not "
                f"see explains: credited beyond that error, the ratio is {cr:.2f} "
                f"({'>' if ratio_max < FURTHER_RATIO_MAX else '>='} {ratio_max:g}; "
                + ", ".join(f"{b} {np.sqrt(max(x['improvement_um2'], 0)):.4f} um against "
                            f"{np.sqrt(x['misfit_um2']):.4f} um" for b, x in bands.items()) + ")")
    if (term.same_on_every_recording and not significant and not refusal and (veto is None or credited_only)
            and ctxs[0] is ctxs[1]):
        # round 19: a static map of y, refused beside the base's history-dependent misfit: judged on what every
        # branch shares at equal y (static_map.py), where that misfit averages out and the map does not
        # credited beyond the base's misfit on held-out calibration histories reduced alike (round 26)
        bc = _branch_common(ctxs[0], term, es[0], fold_all, best_st[0])
        if bc is not None and dbic < 0 and _common_passes(bc, within, p_max):
            whole = {"branch_common": bc, "fold_ratios": list(fold_ratios), "credited_ratio": cr, "p": p}
            fold_ratios, p, cr = list(bc["fold_ratios"]), bc["p"], bc["credited_ratio"]
            significant, veto, credited_only = True, None, False
    if significant and term.sized_inside_calibration:   # round 25: a map of the reading shows inside the range
        why = inside_calibrated_veto(ctxs[0], rb_res, pred_after[used], fold_all[used], within)
        if why:
            significant, veto, credited_only = False, why, False
    for c in ctxs:   # every setting's stacked regressors (about 1M rows each at full length): only this
        c.design_cache.clear()   # evaluation uses them; kept, they held 1.9 GB at the peak (docs/diagnose-speed.md)
    from .signature import HELDOUT_CHECKED
    held = None
    if term.name in HELDOUT_CHECKED and significant:   # its signature check reads them (one term: arrays of the
        e_all = np.zeros(fold_all.size)                # data's length)
        for f in (0, 1):
            e_all[fold_all == 1 - f] = es[f][fold_all == 1 - f]
        p_small, p_big = _beside_unlimited(ctxs, term, es, fold_all, rows, best_st)
        q_small, q_big = _beside_below(ctxs, term, es, fold_all, rows, best_st)
        held = (rb_res, pred_after[used], fold_all[used], block_all[used], rec, e_all[used], p_small[used],
                p_big[used], q_small[used], q_big[used])
    return Candidate(term=term, ratio=na / nb if nb > 0 else 1.0, fold_ratios=fold_ratios, nrmse_before=nb,
                     nrmse_after=na, t=t, p=p, n_active=n_act, p_max=p_max, dbic=dbic, n_eff=neff,
                     significant=significant, setting=[c[0] for c in chosen], coef=[c[4] for c in chosen],
                     veto=veto, credited=cr, credited_bands=bands, ratio_max=ratio_max, heldout=held, whole=whole,
                     credited_only=credited_only)


def _linearized_gates(fold_ratios, p: float, dbic: float, whole: dict | None, p_max: float, within,
                      first_size_gate: bool = True, above_p: bool = True) -> bool:
    """The linearized gates: size (``within`` on the larger fold ratio), the block test (``p_max``) and BIC.

    Round 23: a term sized above an edge (``whole`` holds ``p_above`` and ``dbic_above``: the mode's) is also
    tested there, where it acts and is sized, not only on the whole band, where a ring is a small share of the
    residual beside the base's slow misfit, which no mode models (s129-052: the whole band's p 1.3e-3, above the
    edge 9.1e-6; s129-021: the whole band's dBIC +8 at whole-band ratios 0.97/0.98, 0.77/0.77 above the edge).
    Two looks at one test: the smaller p counts twice (Bonferroni). BIC passes in either view only under the first
    round's size gate (``first_size_gate``: 0.8 above the edge); once a term is in the model the size gate is 1.0
    and the whole band's BIC is the size guard left (kept runs of seeds 127 to 130: eight mode candidates beside a
    slew limit, a rate term or a delay with dBIC +7 to +18 on the whole band and p above the edge passing). The
    figures go to ``whole`` (``p_gate``, ``dbic_gate``; ``whole_band_gates``: what the whole band alone said).

    Round 24: ``above_p`` False (a drive-side term - delay, bandwidth, slew limit - is in the model) drops the
    block test's view above the edge: the whole band's p alone, as before round 23. That term acts in the same
    band as the mode, above the calibration's; high-passed at the edge, the residual is mostly what its model
    leaves there (its grid setting, the base's unidentified continuation now driven through it, the stage's own
    first mode on a slow design) with the slow misfit that would dilute it filtered out, so any such leftover tests
    as a ring (s131-007, a 2 ms delay on a 28 Hz calibration: the stage's first mode 1181 Hz named second at 1205
    Hz, p above the edge 1.2e-9, the whole band's 2.9e-2). On the whole band the mode must lower what the model
    with that term leaves, everywhere. ``p_gate_above``: what the two looks would have given (recorded).

    Returns
    -------
    bool
        Whether the candidate passes the three gates.
    """
    size = bool(within(max(fold_ratios)))
    if whole is None or "p_above" not in whole:
        return bool(size and p < p_max and dbic < 0)
    both = min(1.0, 2.0 * min(p, whole["p_above"]))
    p_gate = both if above_p else p
    dbic_gate = min(dbic, whole["dbic_above"]) if first_size_gate else dbic
    whole.update(p_gate=p_gate, dbic_gate=dbic_gate, whole_band_gates=bool(size and p < p_max and dbic < 0),
                 p_gate_above=both, p_above_counted=bool(above_p))
    return bool(size and p_gate < p_max and dbic_gate < 0)


def _above_edge_evidence(e_before, correction, blocks, rec, dt: float, edge_hz: float, k: int = 1) -> dict:
    """The block test, BIC and the correction's energy share above ``edge_hz`` (rounds 21, 23).

    Parameters
    ----------
    e_before, correction : ndarray
        The held-out residual before the term (nested) and the term's held-out predicted correction [um], used
        samples.
    blocks, rec : ndarray of int
        Block and recording label of each sample.
    dt : float
        Sample period [s].
    edge_hz : float
        The edge the term is sized above [Hz].
    k : int
        The term's parameter count, as for the whole band's BIC.

    Returns
    -------
    dict
        ``p_above``: :func:`significance.active_block_test` on the residual before and after the term, both
        high-passed at the edge per recording as :func:`misfit.ratios_above` does; ``dbic_above``:
        :func:`significance.bic_delta` on those high-passed residuals (their effective sample count);
        ``share_above``: the share of the correction's energy above the edge (of the recordings long enough to
        filter).
    """
    hb, done = above_per_recording(e_before, rec, dt, edge_hz)
    hc, _ = above_per_recording(correction, rec, dt, edge_hz)
    ha = hb - hc
    c = np.asarray(correction, float)
    tot = float(np.sum(c[done] ** 2))
    share = float(np.sum(hc[done] ** 2) / tot) if tot > 0 else 0.0
    units = sg.test_units(hb[done], np.asarray(blocks)[done], np.asarray(rec)[done], dt, hc[done])
    _, p, _ = sg.active_block_test(hb[done], ha[done], hc[done], np.asarray(blocks)[done], units)
    dbic = sg.bic_delta(float(np.sum(hb[done] ** 2)), float(np.sum(ha[done] ** 2)), sg.effective_n(hb[done]), k)
    return {"p_above": float(p), "dbic_above": float(dbic), "share_above": share}


def _common_passes(bc, within, p_max) -> bool:
    """The branch-common test ``bc`` (:func:`_branch_common`) meets the first round's gates: fold ratios and credited
    ratio ``within`` the size gate, p below ``p_max``, and the map fitted on the other recordings lowers each one's
    common part."""
    return bool(within(max(bc["fold_ratios"])) and bc["p"] < p_max and within(bc["credited_ratio"])
                and bc["per_recording"] and max(bc["per_recording"].values()) < 1.0)


def _branch_common(ctx, term, e, fold_all, setting):
    """``static_map.branch_common_test`` of ``term`` at ``setting`` on the used samples of the context ``ctx``
    (the first round's: one model for both folds), nested against the term's nuisance but its own test nuisance:
    the curve's dynamics corrections (round 20) are derivatives of the output, of opposite sign on the rising and
    falling branches at equal y; their common part is near zero, and a fit of it is not determined (s123-026: the
    common part's "before" 0.41 -> 0.95 um, p 2e-4 -> 2e-2). The common part already leaves out what they take."""
    used = fold_all >= 0
    y = np.concatenate([s.yb[v] for s, v in zip(ctx.signals, ctx.valid)])[used]
    br, n0 = [], 0
    for s, v in zip(ctx.signals, ctx.valid):
        b = static_map.branches(s.u)[v] + n0
        n0 = int(b.max()) + 1 if b.size else n0
        br.append(b)
    N = term_nuisance(ctx, term, own_test=False)
    X = _design(ctx, term, setting).X[used]
    br = np.concatenate(br)[used]
    bc = static_map.branch_common_test(y, br, e[used], X, None if N is None else N[used], fold_all[used])
    if bc is not None:   # the same map on every recording: the others' map lowers each one's common part
        rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(ctx.valid)])[used]
        bc["per_recording"] = {ctx.names[i]: r for i, r in static_map.across_recordings(y, br, rec, e[used],
                                                                                          X).items()}
        # credited beyond the base's misfit on held-out calibration histories reduced to its own common part
        # (round 26, static_map.common_misfit: its lag averages out there as the recordings' does); the whole
        # misfit energy (round 19's upper bound) where no history could be reduced
        bc["credited_ratio"] = _one_band_credited(bc["before_um"] ** 2, bc["after_um"] ** 2,
                                                  common_misfit_um2(ctx.misfit))
    return bc


def common_misfit_um2(misfit: dict | None) -> float:
    """The base's misfit energy [um^2] the branch-common reading is credited beyond: ``misfit["common_um2"]``
    (``static_map.common_misfit``) when the histories could be reduced, else the whole excess energy per sample
    (every band of ``misfit["mse_um2"]``); 0 without a misfit estimate."""
    if not misfit:
        return 0.0
    if misfit.get("common_um2") is not None:
        return float(misfit["common_um2"])
    return float(sum(misfit["mse_um2"].values()))


def _beside_unlimited(ctxs, term, es, fold_all, rows, settings):
    """Held-out predictions of the drive term with its setting unbounded (``inf``: the drive unchanged, only the
    dynamics refitted on the calibration as the term refits them) and of that plus the term at ``settings[f]``,
    both nested as in :func:`_evaluate`: what the term takes beyond its own refit of the dynamics
    (``signature.check_slew_absent``)."""
    p_small, p_big = np.zeros(fold_all.size), np.zeros(fold_all.size)
    for f in (0, 1):
        ctx, e = ctxs[f], es[f]
        train, test = fold_all == f, fold_all == 1 - f
        N = _nuis(ctx, term, train, test, rows)
        x0 = _design(ctx, term, float("inf")).X
        x1 = _design(ctx, term, settings[f]).X
        lb = term.lower(ctx)
        p_small[test] = _fit_predict(x0, e, train, test, rows, lb, N)[1]
        p_big[test] = _fit_predict(np.hstack([x0, x1]), e, train, test, rows,
                                   None if lb is None else list(lb) * 2, N)[1]
    return p_small, p_big


def _beside_below(ctxs, term, es, fold_all, rows, settings):
    """Round 27: held-out predictions of the nested nuisance fitted only where the slew limit at ``settings[f]``
    does not act, nor for one guard before or after (``signature.below_limit`` with ``limited`` and ``ahead``), and
    of that plus the term fitted on what the nuisance leaves on the whole training fold
    (``signature.check_slew_absent``).

    A slew limit changes nothing where the drive's rate stays below it, so the rate-independent corrections the
    term is nested against (the dynamics corrections, the hysteresis groups) can be identified there and carried
    to the samples above the limit; only what the limit adds beyond them is its own. Fitted on every sample
    instead, those corrections compromise between the rates and the term is credited with relieving them (null
    s137-036: a lag growing linearly with frequency, 5 deg at 44 Hz to 20 deg at 262 Hz, taken above the limit
    by the term and improving the sines below it through the refitted corrections, fold ratios 0.68/0.62)."""
    from .signature import _nperseg, below_limit
    p_small, p_big = np.zeros(fold_all.size), np.zeros(fold_all.size)
    for f in (0, 1):
        ctx, e = ctxs[f], es[f]
        us = [np.asarray(s.u, float)[v] for s, v in zip(ctx.signals, ctx.valid)]
        below = np.concatenate(below_limit(us, ctx.dt, float(settings[f]), _nperseg([u.size for u in us], ctx.dt),
                                           limited=True, ahead=True))
        train, test = fold_all == f, fold_all == 1 - f
        r = e.copy()
        nb = _nuis(ctx, term, train & below, test, rows)
        if nb is not None and np.any(train & below):
            idx_b = train_rows(train & below, rows)
            lo, hi = nb[2] if nb[2] is not None else (np.full(nb[0].shape[1], -np.inf), np.full(nb[0].shape[1], np.inf))
            th = _lstsq_box(nb[0], e[idx_b], lo, hi)
            p_small[test] = nb[1] @ th
            idx = train_rows(train, rows)
            r[idx] = e[idx] - _nuis(ctx, term, train, test, rows)[0] @ th
        x1 = _design(ctx, term, settings[f]).X
        p_big[test] = p_small[test] + _fit_predict(x1, r, train, test, rows, term.lower(ctx))[1]
    return p_small, p_big


def model_with(base, terms):
    """``base`` (which may already have terms) with ``terms`` added; a drive-dynamics term brings its refitted G,
    a nested term its refitted hysteresis."""
    ref = dict(base)
    ref["terms"] = dict(base.get("terms", {}) or {})
    for k, v in terms.items():
        v = dict(v)
        dyn = v.pop("_dynamics", None)
        if dyn is not None:
            ref["dynamics"] = dyn
        hyst = v.pop("_hysteresis", None)
        if hyst is not None:
            ref["hysteresis"] = hyst
        ref["terms"][k] = v
    return ref


def simulate_refined(params, recs, names):
    """Model output per recording, with the per-recording sensor offsets where the recording is known."""
    out = []
    off = params["terms"].get("sensor_offset")
    for r, n in zip(recs, names):
        y = refined.simulate(params, r.t, r.u, r.u2, session_start(r))
        if off is not None:
            y = y + off["per_recording"].get(n, off["offset_um"]) - off["offset_um"]
        out.append(y)
    return out


def rebase(ctx, params, recs):
    """The context re-derived from ``params`` by exact simulation: every later candidate's signals (H output,
    hysteretic part, dynamics, output) come from the refined model, not from the base."""
    off = float(params["hysteresis"].get("offset", 0.0))
    po = params.get("terms", {}).get("sensor_offset")
    sigs = []
    for s, r in zip(ctx.signals, recs):
        p = refined.simulate_parts(params, r.t, r.u, r.u2, s.t_session)
        y = p["y"]
        if po is not None:
            y = y + po["per_recording"].get(s.name, po["offset_um"]) - po["offset_um"]
        sigs.append(dataclasses.replace(s, v=p["v"], h=p["h"], hyst=p["hyst"], yb=y, ydyn=p["y_dyn"] + off))
    cal_h = [refined.simulate_parts(params, r.t, r.u, r.u2)["h"] for r in ctx.cal]
    return dataclasses.replace(ctx, base=params, signals=sigs, cal_h=cal_h, refit_cache={}, design_cache={},
                               nuisance=None, dyn_nuisance=None, init_nuisance=None)


def _exact_fold(ctx, c: Candidate, f, fold_all, recs) -> dict:
    """Exact check of candidate ``c`` in fold f: its term (setting and coefficients fitted on fold f) added to the
    fold-f model, the recordings simulated, the error scored on fold 1 - f against the model without it."""
    new = model_with(ctx.base, {c.name: c.term.term(ctx, c.setting[f], c.coef[f])})
    ys = simulate_refined(new, recs, ctx.names)
    e_new = np.concatenate([(s.y - y)[v] for s, y, v in zip(ctx.signals, ys, ctx.valid)])
    e_old = residual(ctx)
    test = fold_all == 1 - f
    rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(ctx.valid)])
    per = [(float(np.sum(e_old[test & (rec == i)] ** 2)), float(np.sum(e_new[test & (rec == i)] ** 2)))
           for i in range(len(ctx.valid))]
    out = {"params": new, "sse_before": float(np.sum(e_old[test] ** 2)), "sse_after": float(np.sum(e_new[test] ** 2)),
           "n": int(np.sum(test)), "ys": ys, "per_recording": per}
    edge = c.whole.get("above_hz") if c.whole else None
    if edge:   # round 19: also above the edge it was sized above (misfit.ratios_above's filter, used samples)
        used = fold_all >= 0
        hb, done = above_per_recording(e_old[used], rec[used], ctx.dt, edge)
        ha, _ = above_per_recording(e_new[used], rec[used], ctx.dt, edge)
        t = done & test[used]
        out["above"] = {"above_hz": float(edge), "sse_before": float(np.sum(hb[t] ** 2)),
                        "sse_after": float(np.sum(ha[t] ** 2)), "n": int(np.sum(t))}
    if c.term.ratio_beyond_level:   # round 22: also beyond each recording's level, fitted on the training fold
        sb, sa = beyond_level_sse(e_old, e_new, rec, fold_all == f, test)
        out["beyond_level"] = {"sse_before": sb, "sse_after": sa, "n": int(np.sum(test))}
    return out


def beyond_level_sse(e_old, e_new, rec, train, test) -> tuple:
    """Round 22: (SSE before, SSE after) [um^2] on the ``test`` samples of the errors ``e_old`` (the model without
    the term) and ``e_new`` (with it), each less its own mean per recording (``rec``: the recording index per sample)
    taken on that recording's ``train`` samples (none: 0). A held drive keeps the hysteresis state the unknown
    history before the recording left, and the base errs there by a level no term that is not itself a level can
    take (coupling s127-019: the refined model's error on the hold recording -843 nm, std 36 nm; the base fitted
    without the coupling errs by the same level); beyond it the ratio is the term's. Held out: the level is learnt
    on the other fold's samples of the same recording."""
    sb = sa = 0.0
    for i in np.unique(rec[test]):
        tr, te = train & (rec == i), test & (rec == i)
        lb, la = (float(np.mean(e_old[tr])), float(np.mean(e_new[tr]))) if tr.any() else (0.0, 0.0)
        sb += float(np.sum((e_old[te] - lb) ** 2))
        sa += float(np.sum((e_new[te] - la) ** 2))
    return sb, sa


def pair_design(ctxs, cands, f):
    """The joint fit of several candidates on fold f's model (``discriminate.separate``): the union of their
    nested tests' nuisances with its bounds, and each candidate's columns at the setting its test chose there."""
    ctx, terms = ctxs[f], [c.term for c in cands]
    parts, lo, hi = [], [], []
    for flag, fn, bound in (("nested", hysteresis_nuisance, np.inf), ("nested_dynamics", dynamics_nuisance, np.inf),
                            ("initial_state", initial_state_nuisance, 1.0)):
        if any(getattr(t, flag) for t in terms):
            N = fn(ctx)
            parts.append(N)
            lo.append(np.full(N.shape[1], -bound))
            hi.append(np.full(N.shape[1], bound))
    cols = []
    for c in cands:   # own columns only: a term's own nuisance (creep's levels per recording, an intercept) would
        X = _design(ctx, c.term, c.setting[f]).X   # credit it, or the other, with any level (an offset's)
        lb = c.term.lower(ctx)
        lb = np.full(X.shape[1], -np.inf) if lb is None else np.asarray(lb, float)
        own = [j for j in range(X.shape[1]) if j not in c.term.nuisance_columns(ctx, X.shape[1])]
        cols.append((X[:, own], lb[own], np.full(len(own), np.inf)))
    if ctx.accepted_flex is not None:   # the accepted terms' own flexibility, free (term_nuisance), before the
        k = len(parts) - (1 if any(t.initial_state for t in terms) else 0)   # initial state's bounded gains
        m = ctx.accepted_flex.shape[1]
        parts.insert(k, ctx.accepted_flex)
        lo.insert(k, np.full(m, -np.inf))
        hi.insert(k, np.full(m, np.inf))
    n = sum(int(np.sum(v)) for v in ctx.valid)
    N = np.hstack(parts) if parts else np.zeros((n, 0))
    return N, np.concatenate(lo) if lo else np.zeros(0), np.concatenate(hi) if hi else np.zeros(0), cols


def own_signature_refuses(c, check=None) -> str | None:
    """Round 28: why the candidate ``c``, an alternative of a pair test, cannot be the effect by its own
    signature, or None. The pair test (``discriminate.separate``) is linearized and blind to the physics: over a
    recording a slow element of creep's chain or a slew limit's refit of G can take a drift's ramp. An alternative
    the tool could not name on these data is no alternative: creep without its tail after the steps (its step
    test, at the level of a term's own hypothesis ``ALPHA``: "no held step, no creep"), a drive-side term or a mode
    whose frequency-domain shape check (``check``, ``signature.check_in_context``) fails.

    Parameters
    ----------
    c : Candidate
        The alternative, with its round's ``slow_signature`` (creep) when the slow signatures ran.
    check : callable, optional
        ``check(candidate)`` -> the shape check's dict (``passed``, ``reason``) or None.

    Returns
    -------
    str or None
        The reason in words, or None when its signature does not refuse it (or has nothing to say).
    """
    if c.name == "creep":
        if c.slow_signature is None:
            return None
        st = c.slow_signature.get("step_response")
        if step_holds(st, sg.ALPHA):
            return None
        return "its own signature, the tail after the steps, does not hold (" + step_phrase(st) + ")"
    if check is None:
        return None
    r = check(c)
    if r is None or r.get("passed", True):
        return None
    return "its own signature check fails: " + str(r.get("reason"))


def _separate(best, evals, fctx, es, fold_all, block_all, rows, log, check=None):
    """The accepted candidate's pair tests against the round's other candidates (``discriminate.separate``);
    sets ``best.separation``. An alternative its own signature refuses (:func:`own_signature_refuses`) gets the
    verdict ``signature`` instead of ``inseparable`` (round 28)."""
    e = np.zeros(fold_all.size)
    for f in (0, 1):
        e[fold_all == 1 - f] = es[f][fold_all == 1 - f]
    rec = np.concatenate([np.full(int(np.sum(v)), i) for i, v in enumerate(fctx[0].valid)])
    best.separation = separate(best, evals, lambda cs, f: pair_design(fctx, cs, f), e, fold_all, block_all, rec,
                               fctx[0].dt, rows)
    for c in fctx:
        c.design_cache.clear()
    for r in best.separation:
        b = next((c for c in evals if c.name == r["name"]), None)
        why = own_signature_refuses(b, check) if r["verdict"] == "inseparable" and b is not None else None
        if why:
            r["verdict"], r["reason"] = "signature", why
            log(f"    pair {best.name}/{r['name']}: not inseparable, {why}")
    for r in best.separation:
        log(f"    pair {best.name}/{r['name']}: {r['verdict']} (alone p {r['named_alone']['p']:.0e}/"
            f"{r['alternative_alone']['p']:.0e}, beyond p {r['named_beyond']['p']:.0e}/"
            f"{r['alternative_beyond']['p']:.0e})")
    alt = best.slow_alternative   # round 15: a drift the offset's levels cannot exclude (slow_signature.attribute)
    if alt:
        best.separation = [r for r in best.separation if r["name"] != alt["name"]] + [
            {"name": alt["name"], "verdict": "inseparable", "reason": alt["reason"]}]
        log(f"    pair {best.name}/{alt['name']}: inseparable ({alt['reason']})")
    g = best.delay_or_pole   # round 20: the delay and the pole told apart (or not) by the magnitude
    if g is not None:
        other = g["other"]
        verdict = "inseparable" if g["verdict"] is None else "a"
        best.separation = [r for r in best.separation if r["name"] != other] + [
            {"name": other, "verdict": verdict, "reason": g["reason"]}]
        log(f"    pair {best.name}/{other}: {verdict} by the gain ({g['reason']})")


def _prefer_containing(best, evals, fctx, es, fold_all, block_all, rows, recs, span, log, check):
    """The pair tests of the accepted candidate (:func:`_separate`); when another significant candidate of a
    different group explains all it does and more (verdict ``b``: held out, it improves beyond the accepted one and
    the accepted one does not beyond it), that one is offered first instead (its exact and signature checks
    again), once. Returns the candidate accepted."""
    _separate(best, evals, fctx, es, fold_all, block_all, rows, log, check)
    alt = next((c for r in best.separation if r["verdict"] == "b" for c in evals
                if c.name == r["name"] and c.significant and not c.veto
                and not (c.term.group and c.term.group == best.term.group)), None)
    if alt is None:
        return best
    log(f"    {alt.name} explains what {best.name} does and more: offered first")
    evals.insert(evals.index(best), evals.pop(evals.index(alt)))
    first = _first_exact(evals, fctx, fold_all, recs, span, log, check)
    if first is alt:
        _separate(alt, evals, fctx, es, fold_all, block_all, rows, log, check)
        return alt
    return best


def exact_ratio(c) -> float:
    """The exact check's pooled held-out NRMSE ratio (after / before, both folds together) of the model the
    candidate ``c`` was accepted with; 1 when it has none."""
    if not c.exact_before or c.exact_after is None:
        return 1.0
    return float(c.exact_after / c.exact_before)


def _slow_before_map(best, evals, fctx, fold_all, recs, span, log, check):
    """Round 27: a map of the reading (``Term.same_on_every_recording``, the sensor curve) accepted while a slow
    term (creep, drift, offset: ``SIGNATURES``) is significant in the same round is put after that term when the slow
    term's exact model lowers the pooled held-out error more than the map's does.

    A sensor curve is one static function of the true position, the same at every time and on every recording;
    creep follows the steps and dwells, a drift the session clock, an offset one sensor session. A slow effect's
    residual on recordings that visit different displacements at different times (a step to each level, a walk
    that wanders as the clock runs, a session at another range) projects onto a function of y, so the curve's
    linearized columns take part of it, while the slow term's own linearized test is weak (creep's all-block fold
    ratios 0.90 / 0.95 where its model on the dwells reaches 0.25: held-out s137-000) and sorts it after the curve.
    The exact models compare the two on equal terms; the one that explains more is named first, and the curve,
    tested again in the next round beside the slow term's model, is named only where its credit survives it
    (held-out s137-000, creep: the curve first at an exact ratio 0.84, creep's model on the dwells 0.27).

    Returns the candidate accepted (``evals`` reordered in place when it changes)."""
    if not best.term.same_on_every_recording:
        return best
    own = exact_ratio(best)
    for c in [c for c in evals if c.name in SIGNATURES and c is not best and c.significant and not c.veto]:
        if _first_exact([c], fctx, fold_all, recs, span, log, check) is not c:
            continue
        if exact_ratio(c) < own:
            log(f"    {c.name} before the map {best.name}: exact ratio {exact_ratio(c):.3f} < {own:.3f}")
            _add_note(c, f"A map of the reading ({best.name}) passed first in this round; its exact model lowers the "
                         f"held-out error less (pooled ratio {own:.2f}) than this term's ({exact_ratio(c):.2f}), "
                         f"so this term is named first and the map is tested again beside it.")
            evals.insert(evals.index(best), evals.pop(evals.index(c)))
            return c
    return best


def _map_within_slow(best) -> str | None:
    """Round 27: why a map of the reading (``Term.same_on_every_recording``) that passed is not named in this round:
    its pair test (``best.separation``) against a slow term (creep, drift, offset: ``SIGNATURES``) gave ``"b"``, the
    slow term's columns explain all the map does and more (held out, the map adds nothing beyond them; they add
    beyond the map). A sensor curve is the same function of y at every time and on every recording; a credit that
    the session clock, the steps or a session's level take entirely is theirs (held-out s138-016, a drift: the curve
    beyond the drift p 0.90, the drift beyond the curve p 1e-7). Unlike :func:`_prefer_containing` the slow term need
    not pass its own gates: the map is refused, not replaced. None when the map stands (or ``best`` is no map)."""
    if not best.term.same_on_every_recording:
        return None
    r = next((r for r in best.separation or [] if r.get("verdict") == "b" and r["name"] in SIGNATURES
              and "named_beyond" in r), None)
    if r is None:
        return None
    nb, ab = r["named_beyond"], r["alternative_beyond"]
    return (f"it is one map of the reading at every time and on every recording, but {r['name']}'s columns explain "
            f"all it does and more (held out, it beyond {r['name']}: fold ratios {nb['fold_ratios'][0]:.2f}, "
            f"{nb['fold_ratios'][1]:.2f}, p = {nb['p']:.1e}; {r['name']} beyond it: {ab['fold_ratios'][0]:.2f}, "
            f"{ab['fold_ratios'][1]:.2f}, p = {ab['p']:.1e}): its credit depends on the time or the recording")


def _discriminate(evals, fctx, fold_all, block_all, recs, fc_hp, log):
    """Drive-side dynamics candidates that all pass: told apart by their exact residual above the calibration's
    band (discriminate.py); reorders ``evals`` in place."""
    dd = [c for c in evals if c.significant and c.term.group == "drive_dynamics"]
    if len(dd) <= 1 or fc_hp <= 0:
        return
    hp = []
    for c in dd:
        c.exact = [_exact_fold(fctx[f], c, f, fold_all, recs) for f in (0, 1)]
        h = np.zeros(fold_all.size)
        for f in (0, 1):
            sel = fold_all == 1 - f
            h[sel] = highpassed(fctx[f], c.exact[f]["ys"], fc_hp)[sel]
        hp.append(h)
    apart, best = [], []
    order, text = discriminate_group(dd, hp, fold_all, block_all, fc_hp, apart, best)
    log("    " + text)
    pos = [i for i, c in enumerate(evals) if any(c is x for x in dd)]
    for i, k in zip(pos, order):
        evals[i] = dd[k]
    for c in dd:
        c.discrimination = text
    for k in apart:
        # round 23: its exact model leaves more fast residual than the best's at the test's level: the fast motion
        # is not its shape, whether or not the best then passes its own checks (held-out s130-053, a delay: the
        # delay refused by its transfer's shape on 3 bins, the slew limit, 2.5 times the delay's fast residual at
        # p 7e-5, was named next)
        dd[k].veto = (f"its exact model leaves more residual above {fc_hp:.0f} Hz than the group's least (paired block "
                      f"test, level {ALPHA_DISC:g}): the fast motion is not its shape")
        log(f"    {dd[k].name}: {dd[k].veto}")
        if {dd[k].name, dd[best[0]].name} == set(LAG_PAIR):   # round 27: lifted if the least's shape fails
            dd[k].lag_apart_from = dd[best[0]].name


LAG_PAIR = ("delay", "amplifier_bandwidth")


def _delay_or_pole(evals, ctx, f_band, log):
    """Round 20: when the delay and the amplifier's pole both pass their nested tests, they took the same lag (both
    lag by about ``w tau`` in band; docs/diagnose-rounds/round-20.md "Round 20: delay and bandwidth"). Their magnitudes tell them
    apart where the drives excite frequencies at which the pole's has fallen (:func:`signature.delay_or_pole` on the
    current model's residual transfer, up to the drives' band): the shape that fits worse at level ``ALPHA`` is
    refused (its shape is the other's); the order of the candidates is kept, so a third one the group's
    discrimination put first (a slew limit) stays first. Where neither fits better both stay, and the one named
    carries the other as an alternative the data cannot tell from it (:func:`_separate`)."""
    pair = [next((c for c in evals if c.name == n and c.significant and not c.veto), None) for n in LAG_PAIR]
    if None in pair or f_band is None:
        return
    from .signature import delay_or_pole, drive_band_hz, transfer
    xs = [np.asarray(s.yb, float)[v] for s, v in zip(ctx.signals, ctx.valid)]
    ys = [np.asarray(s.y, float)[v] for s, v in zip(ctx.signals, ctx.valid)]
    us = [np.asarray(s.u, float)[v] for s, v in zip(ctx.signals, ctx.valid)]
    tr = transfer(xs, ys, ctx.dt)
    if tr is None:
        g = {"verdict": None, "figures": {}, "reason": "the recordings give no informative bin of the residual's transfer"}
    else:
        g = delay_or_pole(tr, ctx.dt, f_band, drive_band_hz(us, ctx.dt))
    log(f"    delay or pole: {g['verdict'] or 'not told apart'} ({g['reason']})")
    for c, o in zip(pair, pair[::-1]):
        c.delay_or_pole = {**g, "other": o.name}
    if g["verdict"] is None:
        return
    win, lose = (pair[0], pair[1]) if g["verdict"] == "delay" else (pair[1], pair[0])
    lose.veto = f"its shape is the {win.name}'s: " + g["reason"]
    lose.delay_or_pole = None


# Round 22: the second test is run only where the lag the base lacks exceeds the loop's latency by more than this many
# times its departure over the blocks from a pure delay's (base_lag): a two-sigma band of the base's own lag error.
LAG_SPREAD_SIGMAS = 2.0


LAG_SPREAD_DELAYS = np.arange(0, 31)   # [samples] the pure delays a block-wise lag profile is compared with


def _block_lags(X_lag, ids, e, Nh=None):
    """(c1 per block, its variance): ``e`` regressed on ``X_lag`` = [c2 column, c1 column of each block] (and the
    common columns ``Nh`` first, when given)."""
    X = X_lag if Nh is None else np.hstack([Nh, X_lag])
    th, *_ = np.linalg.lstsq(X, e, rcond=None)
    r = e - X @ th
    s2 = float(r @ r) / max(e.size - X.shape[1], 1)
    return th[-ids.size:], s2 * np.diag(np.linalg.pinv(X.T @ X))[-ids.size:]


def _block_factors(C, b, order, bounds, rhs=()):
    """The least-squares problems of :func:`base_lag` by blocks: ``X = [C, b x (block == j) for each block j]``
    (n, m + nb), never formed. Each block's rows ``[C_j, b_j]`` are factored ``Q_j R_j`` (reduced QR); the stacked
    ``R_j``, with ``b``'s column moved to column ``m + j``, form ``S`` (sum of the blocks' ranks, m + nb), and
    ``X = diag(Q_j) S`` up to the rows' order, ``diag(Q_j)`` with orthonormal columns. So ``S`` has ``X``'s singular
    values and right vectors: ``S' S = X' X``, ``pinv(X) z = pinv(S) diag(Q_j)' z``, and the least-squares fit of
    ``z`` on ``X`` is that of ``diag(Q_j)' z`` on ``S``, equal in exact arithmetic. Returns ``S``, the stacked
    ``Q_j' z`` for each array in ``rhs`` (n,), and the ``Q_j`` when ``rhs`` is empty (for later right-hand sides).

    Round 23: ``X`` had a column per time block (about 110 on s0-017, 1.1 M rows: 1 GB), and its SVDs
    (``np.linalg.pinv``, ``lstsq``) took 57 of that case's 146 s CPU and its resident peak to 3.5 GB."""
    m = C.shape[1]
    nb = bounds.size - 1
    S, Qz, Qs = [], [[] for _ in rhs], []
    for j in range(nb):
        r = order[bounds[j]:bounds[j + 1]]
        Q, R = np.linalg.qr(np.column_stack([C[r], b[r]]))
        row = np.zeros((R.shape[0], m + nb))
        row[:, :m] = R[:, :m]
        row[:, m + j] = R[:, m]
        S.append(row)
        for i, z in enumerate(rhs):
            Qz[i].append(Q.T @ z[r])
        if not rhs:
            Qs.append(Q)
    return np.vstack(S), [np.concatenate(q) for q in Qz], Qs


def base_lag(ctx, e, block_all) -> tuple | None:
    """Round 22: (lag, spread) [samples]: the pure delay whose profile over the time blocks best fits the lags the
    base's G lacks, and how far those lags are *not* a delay's: the weighted RMS over the time
    blocks of the lag ``c1`` fitted to the residual ``e`` per block (the first difference of the model's dynamic
    output, a free gain per block; the hysteresis channels and ``c2`` common to all blocks) about the best profile
    of a pure delay (the same fit of ``y(t - D) - y(t)`` for ``D`` in ``LAG_SPREAD_DELAYS``), weights the inverse
    variance of each block's ``c1``.

    The physics: a delay, or the loop's latency, is a phase ``-w d`` at every frequency; its first-order part
    ``c1`` seen by a block depends on the band the block's drive excites only as a delay's does (``sin(w d) / w``:
    a long delay looks shorter to a fast block), and the profile of a pure delay follows that. What G lacks beyond
    it - a pole or a mode above the calibration's band, the hysteresis misfit that looks like a phase at a slow
    block's frequency - is a phase that is not ``w d``, and the lags the blocks see leave any delay's profile. So
    the departure is how well G's phase at the drives' band is known as a lag: a lag beyond the latency within it
    is G's own error, not a drive-side term's (development, studied: the null s127-036, G of order 0, the blocks'
    lags 2.4 to 10 samples; the true 2-sample delay s127-022, the same mean lag 4.1 and lags 3.9 to 5.3; the
    1.0 ms delay s125-053, 11 samples, whose blocks' lags depart from a delay's by 2.4). None where it cannot be
    computed."""
    if e is None or block_all is None:
        return None
    ids = np.unique(block_all)
    if ids.size < 2:
        return None
    D = dynamics_nuisance(ctx)
    # round 23: the fits of _block_lags (X = [Nh, c2 column, c1 column of each block]) and the pure delay's
    # (pinv of [c2 column, c1 column of each block]) from the blocks' QR factors (_block_factors), the same
    # problems as the stacked columns', without them
    _, inv = np.unique(block_all, return_inverse=True)
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(ids.size + 1))
    Nh = hysteresis_nuisance(ctx)
    C = np.hstack([Nh, D[:, 1:2]])
    S, (Qe,), _ = _block_factors(C, D[:, 0], order, bounds, (e,))
    n, p = e.size, S.shape[1]
    th, *_ = np.linalg.lstsq(S, Qe, rcond=np.finfo(float).eps * max(n, p))   # lstsq's default cutoff on X
    r = e - C @ th[:C.shape[1]] - D[:, 0] * th[C.shape[1]:][inv]
    s2 = float(r @ r) / max(n - p, 1)
    c, var = th[-ids.size:], s2 * np.diag(np.linalg.pinv(S.T @ S))[-ids.size:]
    ok = var > 0
    if ok.sum() < 2:
        return None
    w = 1.0 / var[ok]
    # a pure delay's block lags: the same fit of y(t - d) - y(t), without the channels
    S_lag, _, Qs = _block_factors(D[:, 1:2], D[:, 0], order, bounds)
    P = np.linalg.pinv(S_lag)
    best, lag = np.inf, 0
    for d in LAG_SPREAD_DELAYS:
        z = np.concatenate([np.concatenate([np.full(d, s.ydyn[0]), np.asarray(s.ydyn, float)[:s.ydyn.size - d]])[v]
                            - np.asarray(s.ydyn, float)[v] for s, v in zip(ctx.signals, ctx.valid)])
        k = (P @ np.concatenate([Q.T @ z[order[bounds[j]:bounds[j + 1]]] for j, Q in enumerate(Qs)]))[-ids.size:]
        r = float(np.sum(w * (c[ok] - k[ok]) ** 2) / np.sum(w))
        if r < best:
            best, lag = r, int(d)
    return float(lag), float(np.sqrt(best))


def _lag_beyond_latency(evals, fctx, es, fold_all, block_all, rows, p_max, accepted, log):
    """Round 21: when no drive-side term passed against the free dynamics corrections, the drive-side terms are
    evaluated again with the corrections' lag ``c1`` bounded to the loop's latency (``_DriveTerm.dynamics_lag_bound``,
    :func:`nuisance_bounds`), and those evaluations replace theirs in ``evals``.

    A delay's phase is ``-w d`` at every frequency; the free ``c1 s`` is its first-order part and, over the whole
    band, took it (round 19's oracle; round 21: the five held-out delay misses of seeds 125/126, true delays 0.7 to
    1.5 ms, refused at fold ratios 0.59 to 0.95 against them and passing at 0.09 to 0.41 against the bounded ones).
    What the base's G can lack in lag is the loop's own latency (round 5's nulls), so the bounded test still
    gives a null's own lag to the corrections. Only as a second test: where a drive term passes against the free
    corrections its lag is plain without the bound, and the bound would hand the other shape the same first-order
    lag (development s113-022: a 0.6 ms delay named alone before, the pole passed beside it with the bound and the
    two were not told apart on 14 bins to 140 Hz). Round 22: only where the lag the base lacks lies beyond the latency
    by more than twice its departure from a pure delay's over the blocks (:func:`base_lag`): within it, the lag is
    G's own error (the null s127-036 had been named `amplifier_bandwidth` x0.75 by this test)."""
    drive = [c for c in evals if getattr(c.term, "dynamics_lag_bound", None) is not None]
    if not drive or any(c.significant and not c.veto for c in drive):
        return evals
    seen = {}
    for i, c in enumerate(fctx):   # round 22: the lag the base lacks, and how far it is a delay's, per fold's model
        if id(c) not in seen:
            seen[id(c)] = base_lag(c, None if es is None else es[i], block_all)
            if seen[id(c)] is not None:
                log("    the lag the base lacks: {:.0f} samples, departing from a delay's over the blocks by {:.2f}"
                    .format(*seen[id(c)]))
    if any(x is not None and x[0] <= float(LATENCY_SAMPLES) + LAG_SPREAD_SIGMAS * x[1] for x in seen.values()):
        log("    the lag beyond the loop's latency lies within the base's own lag error: no second test")
        return evals
    for c in fctx:
        c.bound_lag = True
    try:
        again = {c.name: _evaluate(fctx, c.term, es, fold_all, block_all, rows, p_max, _ratio_max(c.term, accepted),
                                   _beside_drive(accepted))
                 for c in drive}
    finally:
        for c in fctx:
            c.bound_lag = False
    for c in drive:
        a = again[c.name]
        a.selection_round = c.selection_round
        a.lag_bounded = True
        log(f"    {c.name} with the corrections' lag bounded to the loop's latency: {a.ratio:.3f} "
            f"({a.fold_ratios[0]:.2f}/{a.fold_ratios[1]:.2f} p {a.p:.0e}, credited {a.credited:.2f})"
            + (" passes" if a.significant and not a.veto else ""))
    return sorted((again.get(c.name, c) for c in evals), key=lambda c: c.ratio)


def _supersede(evals):
    """A significant candidate that contains a simpler significant one as its nuisance (``Term.supersedes``: it
    passed *beyond* the simpler term's fit, e.g. a drift within recordings beyond a constant per recording) goes
    just before it; reorders ``evals`` in place."""
    for c in [c for c in evals if c.significant and c.term.supersedes]:
        i = evals.index(c)
        simpler = [j for j, o in enumerate(evals[:i]) if o.significant and o.name in c.term.supersedes]
        if simpler:
            evals.insert(simpler[0], evals.pop(i))


def _worsened(ex, names):
    """(recording, factor) of the recording whose held-out RMS error (both folds) the term raises most, when
    beyond ``WORSEN_MAX``; else None. Reported with the effect, not a veto: as a veto (round 7) it also refused
    a true rate dependence and a true creep on held-out cases, whose refined models made a slow in-range
    triangle 2.7 to 3.1x worse at the noise floor (their effect depends on each recording's history). A veto only
    for a term that is the same map on every recording (``Term.same_on_every_recording``: the sensor's curve)."""
    worst = None
    for i, n in enumerate(names):
        b = sum(x["per_recording"][i][0] for x in ex)
        a = sum(x["per_recording"][i][1] for x in ex)
        if b <= 0:
            continue
        k = float(np.sqrt(a / b))
        if k > sg.WORSEN_MAX and (worst is None or k > worst[1]):
            worst = (n, k)
    return worst


def _lift_lag_apart(evals, c, log):
    """Round 27: the delay and the amplifier's pole are both linear lags sized with G refitted on the calibration
    (below its band), so above that band their exact models differ mostly by the refitted G's continuation, where
    the calibration says nothing; the group's fast residual (``_discriminate``) then orders the pair but cannot
    refuse the other lag once the least one's own transfer shape has failed (round 26's held-out s138-038, a 1.1 ms
    delay on a Coleman-Hodgdon stage: the pole left 0.44 of the delay's fast residual and failed its pole shape,
    F 1.11). The refused partner gets its own shape and exact checks. A slew limit's refusal stays: its excess fast
    residual is a ramp's shape, which no continuation of a linear G gives."""
    for o in evals:
        if o.lag_apart_from == c.name and o.veto and "than the group's least" in o.veto:
            o.veto, o.lag_apart_from = None, None
            _add_note(o, f"{c.name}, which left less fast residual, failed its own shape check, so {o.name} was "
                         f"checked on its own shape.")
            log(f"    {o.name}: refused only by {c.name}'s fast residual, whose own shape failed: checked on its own")


def _setting_of(c):
    """The candidate's setting for its signature check: a mode's (freq, damping) of fold 0, else the mean of the
    folds' scalar settings."""
    st = c.setting[0]
    if isinstance(st, (int, float, np.number)) and all(isinstance(x, (int, float, np.number)) for x in c.setting):
        return float(np.mean([float(x) for x in c.setting]))
    return st   # a mode's tuple, or a setting of a term without a signature check (not read)


def _first_exact(evals, fctx, fold_all, recs, span, log, check=None):
    """The first significant candidate whose exact refined model lowers the held-out error in each fold (and,
    with ``check``, whose shape passes its signature check: ``check(candidate)`` -> dict or None)."""
    for c in evals:
        if not c.significant or c.veto:
            continue
        if c.below_gates and check is None and c.name not in SIGNATURES:
            c.veto = ("after the first term it passed only below the first round's size gates, and no signature "
                      "check ran")
            continue
        if check is not None:
            c.signature_check = check(c) or c.signature_check   # a check of its own (coupling's) is kept
            if c.below_gates and c.name not in SIGNATURES and not (c.signature_check or {}).get("testable", False):
                c.veto = ("after the first term it passed only below the first round's size gates, where its "
                          "signature must hold, and its signature check has no informative bin to test it on")
                log(f"    signature {c.name}: {c.veto}")
                continue
            if c.signature_check is not None:
                log(f"    signature {c.name}: " + ("passed" if c.signature_check["passed"] else "failed") + " "
                    + ", ".join(f"{k} {v:.3g}" for k, v in c.signature_check["figures"].items()
                                if isinstance(v, (int, float))))
            if c.signature_check is not None and not c.signature_check["passed"]:
                c.veto = "its signature check fails: " + c.signature_check["reason"]
                log(f"    signature {c.name}: {c.veto}")
                _lift_lag_apart(evals, c, log)
                continue
        ex = c.exact or [_exact_fold(fctx[f], c, f, fold_all, recs) for f in (0, 1)]
        c.exact_fold_ratios, c.exact_before, c.exact_after = _exact_figures(ex, span)
        log(f"    exact {c.name}: {c.exact_fold_ratios} {c.exact_before:.4f} -> {c.exact_after:.4f}")
        c.exact_above = _exact_above(ex, span)
        c.exact_beyond_level = _exact_beyond_level(ex, span)
        worse = _worsened(ex, fctx[0].names)
        if max(c.exact_fold_ratios) < 1.0 and worse and c.term.same_on_every_recording:
            # round 17: a static map of the reading is the sensor's, the same on every recording it reads; a fit
            # that makes one of them worse is another recording's misfit (null s117-018: x4.64 on the triangle)
            c.veto = (f"it is a property of the sensor, the same on every recording, but its exact refined model "
                      f"makes {worse[0]} worse (held-out error x{worse[1]:.2f} > {sg.WORSEN_MAX:g})")
            log(f"    {c.name}: {c.veto}")
            continue
        if max(c.exact_fold_ratios) < 1.0 and c.exact_above and max(c.exact_above["fold_ratios"]) >= 1.0:
            # round 22: a term sized above an edge (a mode: above f / sqrt(2)) passed its linearized gates there;
            # its exact model must lower the error there too. Where it lowers the whole band's error but raises the
            # error above its edge, what it takes is below the edge: its static share standing in for the base's
            # gain or a first term's residual (null s128-054: whole 0.30, above 1.55; beside slew limits s126-024,
            # s127-024, s128-055: above 1.7 to 4.9; the true modes named: above 0.18 to 0.80)
            fa = c.exact_above["fold_ratios"]
            c.veto = (f"its exact refined model lowers the held-out error in each fold (ratios "
                      f"{c.exact_fold_ratios[0]:.2f}, {c.exact_fold_ratios[1]:.2f}) but not above "
                      f"{c.exact_above['above_hz']:.0f} Hz, where it was sized and acts (ratios {fa[0]:.2f}, "
                      f"{fa[1]:.2f}): what it takes lies below its edge")
            log(f"    {c.name}: {c.veto}")
            continue
        if max(c.exact_fold_ratios) < 1.0:
            c.exact = ex
            c.worsened = worse
            return c
        c.veto = ("the exact simulation of the refined model with this term does not lower the held-out "
                  f"error in each fold (ratios {c.exact_fold_ratios[0]:.2f}, {c.exact_fold_ratios[1]:.2f})")
        if c.dwell_coef is not None and _exact_on_dwells(c, fctx, fold_all, recs, span, log):
            return c
        if c.cycle_coef is not None and _exact_on_cycles(c, fctx, fold_all, recs, span, log):
            return c
        if c.term.same_on_every_recording and fctx[0] is fctx[1] and _exact_per_recording(c, ex, fctx[0].names,
                                                                                          log):
            return c
        if c.term.same_on_every_recording and fctx[0] is fctx[1] and _exact_on_common(c, fctx, fold_all, recs,
                                                                                       span, log):
            return c
    return None


def per_recording_ratios(ex) -> list:
    """Round 23: per fold, the geometric mean over the recordings of the held-out RMS error ratio (with the term /
    without it) of the exact check's sums ``ex`` (``_exact_fold``'s ``per_recording``); each recording weighs alike,
    whatever the base's misfit on it. A recording without held-out error in a fold is left out; none at all: 1."""
    out = []
    for x in ex:
        r = [0.5 * np.log(a / b) for b, a in x["per_recording"] if b > 0 and a > 0]
        out.append(float(np.exp(np.mean(r))) if r else 1.0)
    return out


def _add_note(c, note: str) -> None:
    """Append a sentence on how an exact check was passed to the candidate's discrimination text."""
    c.discrimination = (c.discrimination + " " + note) if c.discrimination else note


def _exact_per_recording(c, ex, names, log) -> bool:
    """Round 23: a map of the reading (``Term.same_on_every_recording``) refused by the pooled exact check, first
    round only, read per recording. The pooled ratio weighs each recording by the base's error on it; a static map
    of y changes every recording alike, but the base's misfit of the hysteresis differs by history, and the one
    recording where it is largest decides (held-out s127-011: the curve halves the error of both triangles in each
    fold, x0.44 to x0.52, while the steps, whose base misfit is five times the curve's, stay at x0.99 / x1.02, pooled
    0.96 / 1.00). Passes when, in each fold, the geometric mean of the recordings' ratios is below 1 and no
    recording is worse than ``WORSEN_MAX`` over both folds (round 17's rule, unchanged): the map must help the typical
    recording and harm none. The pooled ratios stay the candidate's ``exact_fold_ratios``; the evidence says so."""
    gm = per_recording_ratios(ex)
    worse = _worsened(ex, names)
    log(f"    exact {c.name} per recording (geometric mean): {[round(x, 3) for x in gm]}"
        + (f", {worse[0]} x{worse[1]:.2f}" if worse else ""))
    if max(gm) >= 1.0 or worse:
        c.veto += (f"; nor with the recordings weighted alike (geometric mean of their held-out ratios {gm[0]:.2f}, "
                   f"{gm[1]:.2f}" + (f"; {worse[0]} x{worse[1]:.2f}" if worse else "") + ")")
        return False
    pooled = list(c.exact_fold_ratios)
    c.exact, c.veto, c.worsened = ex, None, None
    note = (f"Its exact check pooled over the recordings gave ratios {pooled[0]:.2f}, {pooled[1]:.2f} (each recording "
            f"weighted by the base's error on it); with the recordings weighted alike it lowers the held-out "
            f"error in each fold (geometric mean of the recordings' ratios {gm[0]:.2f}, {gm[1]:.2f}) and makes none "
            f"worse than x{sg.WORSEN_MAX:g}.")
    _add_note(c, note)
    return True


def _exact_on_common(c, fctx, fold_all, recs, span, log) -> bool:
    """Round 20: a map of the reading (``Term.same_on_every_recording``) refused by the exact check, with its model
    sized on each fold's branch-common part (``static_map.branch_common_test``'s ``coef``), first round only. The
    whole residual's fit takes the base's misfit on one recording's histories (held-out s124-026: 0.61 um beside
    the steps' 0.20 um curve, 0.03 um on the triangles; fold 0's c2, c3 -1.29, +1.31 against the true curve's
    projection -0.50, +0.11, the common part's -0.60, -0.32), and its model makes the triangles worse. Offered only
    when the common test meets the first round's gates (:func:`_common_passes`), then checked exactly as every
    candidate is: each fold's held-out error lower, no recording worse than ``WORSEN_MAX``. When it passes it
    becomes the candidate's model and the refusal is lifted; its fold ratios are reported beside the refused ones."""
    ctx = fctx[0]
    bc = (c.whole or {}).get("branch_common")
    if bc is None:
        bc = _branch_common(ctx, c.term, residual(ctx), fold_all, c.setting[0])
        if bc is None:
            return False
    within = (lambda x: x <= c.ratio_max) if c.ratio_max < FURTHER_RATIO_MAX else (lambda x: x < c.ratio_max)
    if not _common_passes(bc, within, c.p_max):
        return False
    refused = list(c.exact_fold_ratios)
    c2 = dataclasses.replace(c, coef=[np.asarray(x, float) for x in bc["coef"]], exact=None)
    ex = [_exact_fold(fctx[f], c2, f, fold_all, recs) for f in (0, 1)]
    fr, before, after = _exact_figures(ex, span)
    worse = _worsened(ex, ctx.names)
    log(f"    exact {c.name} sized on the branch-common part: {fr}" + (f", {worse[0]} x{worse[1]:.2f}" if worse else ""))
    if max(fr) >= 1.0 or worse:
        c.veto += (f"; nor sized on what every branch shares at equal y (ratios {fr[0]:.2f}, {fr[1]:.2f}"
                   + (f"; {worse[0]} x{worse[1]:.2f}" if worse else "") + ")")
        return False
    c.coef, c.exact, c.exact_fold_ratios, c.veto = list(c2.coef), ex, fr, None
    c.exact_before, c.exact_after, c.worsened = before, after, None
    note = (f"Its model fitted on the whole residual was refused by the exact check (ratios {refused[0]:.2f}, "
            f"{refused[1]:.2f}: the base's misfit on some histories takes the curve's columns); sized on what every "
            f"branch shares at equal y it lowers the held-out error in each fold (ratios {fr[0]:.2f}, {fr[1]:.2f}).")
    _add_note(c, note)
    return True


def _exact_resized(c, c2, fctx, fold_all, recs, span, log, short: str, where: str):
    """The exact check of ``c`` with its model sized elsewhere (``c2``: on the dwells, round 19; on a repeated drive's
    cycles, round 26). Returns ``(ex, fold ratios, before, after)`` when it lowers each fold's held-out error; else
    adds the refusal to ``c.veto`` and returns None."""
    ex = [_exact_fold(fctx[f], c2, f, fold_all, recs) for f in (0, 1)]
    fr, before, after = _exact_figures(ex, span)
    log(f"    exact {c.name} sized on {short}: {fr}")
    if max(fr) >= 1.0:
        c.veto += f"; nor sized on {where} (ratios {fr[0]:.2f}, {fr[1]:.2f})"
        return None
    return ex, fr, before, after


def _exact_on_dwells(c, fctx, fold_all, recs, span, log) -> bool:
    """Round 19: creep's model sized on the dwells after the steps (``c.dwell_coef``), exactly checked when the one
    fitted on all blocks was refused; when it lowers the held-out error in each fold it becomes the candidate's
    model (``from_dwells``) and the refusal is lifted. Its fold ratios are reported beside the refused ones."""
    refused = list(c.exact_fold_ratios)
    c2 = dataclasses.replace(c, coef=list(c.dwell_coef), exact=None)
    got = _exact_resized(c, c2, fctx, fold_all, recs, span, log, "the dwells", "the dwells after the steps")
    if got is None:
        return False
    ex, fr, before, after = got
    c.coef, c.exact, c.exact_fold_ratios, c.from_dwells, c.veto = list(c.dwell_coef), ex, fr, True, None
    c.exact_before, c.exact_after = before, after
    c.worsened = _worsened(ex, fctx[0].names)
    note = (f"Its model fitted on all blocks was refused by the exact check (ratios {refused[0]:.2f}, "
            f"{refused[1]:.2f}: the base's misfit there takes creep's columns); sized on the dwells after the steps "
            f"(the time constants up to the longest dwell, the base's loop kept) it lowers the held-out error in "
            f"each fold (ratios {fr[0]:.2f}, {fr[1]:.2f}).")
    _add_note(c, note)
    return True


def _exact_on_cycles(c, fctx, fold_all, recs, span, log) -> bool:
    """Round 26: a significant drift's model sized on a repeated drive's cycles (``c.cycle_coef``), exactly checked
    when the one fitted on every block was refused; when it lowers the held-out error in each fold it becomes the
    candidate's model (``from_cycles``, as round 25's drift sized there) and the refusal is lifted."""
    refused = list(c.exact_fold_ratios)
    c2 = dataclasses.replace(c, setting=[x[0] for x in c.cycle_coef], coef=[x[1] for x in c.cycle_coef], exact=None)
    got = _exact_resized(c, c2, fctx, fold_all, recs, span, log, "the cycles", "the repeated drive's cycles")
    if got is None:
        return False
    ex, fr, before, after = got
    c.setting, c.coef, c.exact, c.exact_fold_ratios = c2.setting, c2.coef, ex, fr
    c.from_cycles, c.veto, c.exact_before, c.exact_after = True, None, before, after
    c.exact_above, c.exact_beyond_level = _exact_above(ex, span), _exact_beyond_level(ex, span)
    c.worsened = _worsened(ex, fctx[0].names)
    _add_note(c, f"Its line fitted on every block was refused by the exact check (ratios {refused[0]:.2f}, "
                 f"{refused[1]:.2f}: the other recordings' levels carry the base's misfit of their histories); sized "
                 f"on the repeated drive's cycles it lowers the held-out error in each fold (ratios {fr[0]:.2f}, "
                 f"{fr[1]:.2f}).")
    return True


def _exact_above(ex, span) -> dict | None:
    """Round 19: the exact check's figures above the edge a term was sized above (``Candidate.whole``'s
    ``above_hz``: a mode's ``f / sqrt(2)`` or the calibration's band), pooled and per fold, from ``_exact_fold``'s
    ``"above"``; None for a term sized on the whole residual. Below the edge the held-out error is the base's
    misfit of its hysteresis and of its own modes, which the term does not act on (s121-021: the pooled exact
    ratio 0.93 with the linearized one above the edge 0.55/0.51)."""
    if not all("above" in x for x in ex):
        return None
    a = [x["above"] for x in ex]
    fr, before, after = _exact_figures(a, span)
    return {"above_hz": a[0]["above_hz"], "fold_ratios": fr, "nrmse_before": before, "nrmse_after": after}


def _exact_beyond_level(ex, span) -> dict | None:
    """Round 22: the exact check's figures beyond each recording's level (``_exact_fold``'s ``"beyond_level"``,
    :func:`beyond_level_sse`), pooled and per fold; None for a term without ``Term.ratio_beyond_level``."""
    if not all("beyond_level" in x for x in ex):
        return None
    fr, before, after = _exact_figures([x["beyond_level"] for x in ex], span)
    return {"fold_ratios": fr, "nrmse_before": before, "nrmse_after": after}


def _exact_figures(ex, span) -> tuple:
    """(fold ratios, pooled NRMSE before, after) of the exact check's per-fold sums ``ex`` (``_exact_fold``'s
    ``sse_before``, ``sse_after``, ``n``); ``span`` [um] normalizes. A fold with nothing before has ratio 1."""
    fr = [float(np.sqrt(x["sse_after"] / x["sse_before"])) if x["sse_before"] > 0 else 1.0 for x in ex]
    n = max(sum(x["n"] for x in ex), 1)
    return (fr, float(np.sqrt(sum(x["sse_before"] for x in ex) / n) / span),
            float(np.sqrt(sum(x["sse_after"] for x in ex) / n) / span))


def _ratio_max(term, accepted) -> float:
    """The size gate ``term`` is tested at: ``FURTHER_RATIO_MAX`` once a term is in the model and ``term`` has a
    signature test of its own (``CHECKED_TERMS``), else ``significance.RATIO_MAX``."""
    return FURTHER_RATIO_MAX if accepted and term.name in CHECKED_TERMS else sg.RATIO_MAX


def _beside_drive(accepted) -> bool:
    """Whether a drive-side term (group ``drive_dynamics``: delay, amplifier bandwidth, slew limit) is among the
    ``accepted`` candidates: it acts above the calibration's band, where a mode is sized (round 24)."""
    return any(a.term.group == "drive_dynamics" for a in accepted)


def _slow_beyond_gates(evals, log):
    """A slow candidate significant only below the first round's size gates is kept when its signature *holds*
    (beyond the other two and the base's misfit at the search level ``ALPHA / 3``, slow_signature.py), not merely
    confirms its own name at ``ALPHA``: below the gates the signature is the evidence; vetoed otherwise."""
    for c in evals:
        if c.significant and not c.veto and c.below_gates and c.name in SIGNATURES:
            sig = c.slow_signature or {}
            if not (sig.get("holds") or sig.get("trend_holds")):   # round 20: the drift's trend, its alone
                c.significant = False
                c.veto = ("after the first term it passed only below the first round's size gates (fold ratios "
                          f"{c.fold_ratios[0]:.2f}/{c.fold_ratios[1]:.2f}, credited {c.credited:.2f}), where its slow "
                          f"signature must hold at {sig.get('alpha', float('nan')):.1e}; it does not (unique ratio "
                          f"{sig.get('unique_ratio', float('nan')):.2f}, p = {sig.get('p_value', float('nan')):.1e})")
                log(f"    {c.name}: {c.veto}")


def _coupling_motion(evals, fctx, es, fold_all, block_all, rows, log, later: bool = False):
    """A significant ``cross_coupling`` candidate is kept only when its improvement follows the other axis'
    *motion*, beyond that axis' level per recording and the slow terms (``coupling_signature.motion_test``, at
    ``significance.ALPHA``); vetoed otherwise (round 14: a drift taken by the columns of the one recording where
    the other axis moved, development s111-016).

    Round 25, ``later`` (a term is in the model): a coupling candidate that lowered the held-out error in each fold,
    credited below 1 and not refused, but not significant, is made significant when its motion test holds at the
    round's own level (``p_max``, not ``ALPHA``) and lowers each fold. Its own test reads the whole residual:
    the per-recording levels and the slow misfit the base and the first term leave (a Preisach-class law's level
    misfit of 0.2 um beside a coupling of 0.3 um that moves only in the recordings where the other axis does)
    swamp its units, while a coupling is what follows the other axis' motion, and the motion test reads exactly
    that, beyond a level per recording and the slow terms (held-out s123-004, creep + coupling on a KP law: after
    creep the coupling's candidate 0.99/0.98, p 6e-2, its improvement 0.11 um RMS in the fast band against 0.02 um
    of the base's fast misfit). The exact check decides as for every candidate."""
    c = next((x for x in evals if x.name == "cross_coupling" and not x.veto), None)
    if c is None:
        return
    on_motion = (later and not c.significant and max(c.fold_ratios) < FURTHER_RATIO_MAX
                 and c.credited < FURTHER_RATIO_MAX)
    if not (c.significant or on_motion):
        return
    from .coupling_signature import motion_phrase, motion_test
    mt = motion_test(fctx, es, [slow_nuisance(x) for x in fctx], c.setting, fold_all, block_all, rows)
    if on_motion:
        holds = bool(mt["p"] < c.p_max and max(mt["fold_ratios"]) < 1.0)
        log(f"    cross_coupling on its motion (not significant on the whole residual, p = {c.p:.1e}): "
            f"{motion_phrase(mt)}: " + (f"holds at {c.p_max:.1e}" if holds else f"does not hold at {c.p_max:.1e}"))
        if holds:
            c.significant = True
            c.signature_check = {"passed": True, "testable": True, "motion": mt, "reason": None,
                                 "figures": {"motion_ratio": mt["ratio"], "motion_p": mt["p"]}}
            c.discrimination = (f"On the whole residual it was not significant (fold ratios {c.fold_ratios[0]:.2f}/"
                                f"{c.fold_ratios[1]:.2f}, p = {c.p:.1e}): the levels and slow misfit left beside it "
                                f"swamp a coupling that moves only where the other axis does; {motion_phrase(mt)}, "
                                f"at the round's level {c.p_max:.1e}.")
        return
    c.signature_check = {"passed": mt["holds"], "testable": True, "motion": mt,
                         "reason": ("its improvement does not follow the other axis' motion: " + motion_phrase(mt)
                                    + f" (level {mt['alpha']:g})"),
                         "figures": {"motion_ratio": mt["ratio"], "motion_p": mt["p"]}}
    log(f"    cross_coupling motion: {motion_phrase(mt)}: " + ("holds" if mt["holds"] else "does not hold"))
    if not mt["holds"]:
        c.significant = False
        c.veto = c.signature_check["reason"]


def _explained_beyond(best, evals) -> dict:
    """Round 22: the beyond-range terms the accepted ``best`` explains beyond the calibrated edge, by its pair tests.

    Two terms that act only beyond the calibrated drive range (``Term.only_beyond_calibrated_range``: the clip, the
    asymmetric knee) are fitted on the same samples beyond the edge. When ``best`` is one of them and its pair test
    with the other gave ``"a"`` (``best`` improves beyond the other, the other does not beyond ``best`` by a named
    effect's size, ``discriminate._both_by_size``), the question a later round would ask of the other - does it add
    beyond ``best`` there? - has been answered, on the same samples, beside ``best`` and the same nuisance. Asked
    again on ``best``'s residual, the other is credited only with what ``best`` left beyond the edge, i.e. with the
    base's unknown continuation there (held-out s128-028, a rail at 19.3 V: the knee passed round 2 at credited
    0.79 on the 3 % of the residual the clip left, after its pair test had found it adding 0.79/0.86 beyond the clip,
    and was named second).

    Parameters
    ----------
    best : Candidate
        The accepted candidate, its pair tests in ``separation``.
    evals : list of Candidate
        The round's candidates (the other's term is read from them).

    Returns
    -------
    dict
        Name -> the reason it is not offered again (empty when ``best`` is not such a term).
    """
    if not getattr(best.term, "only_beyond_calibrated_range", False):
        return {}
    beyond = {c.name for c in evals if getattr(c.term, "only_beyond_calibrated_range", False)}
    out = {}
    for r in best.separation or []:
        if r.get("verdict") != "a" or "alternative_beyond" not in r or r["name"] not in beyond:
            continue
        fr = r["alternative_beyond"]["fold_ratios"]
        out[r["name"]] = (f"beyond the calibrated range its pair test with {best.name} (round {best.selection_round}) "
                          f"found it not improving beyond {best.name} at its level and a named effect's size (fold ratios {fr[0]:.2f}/"
                          f"{fr[1]:.2f}, p = {r['alternative_beyond']['p']:.1e}); after {best.name} it would be "
                          f"credited with what {best.name} left there, the base's continuation")
    return out


def _veto_explained(evals, explained: dict, log) -> None:
    """Vetoes the candidates ``explained`` names (:func:`_explained_beyond`) in place; evaluated and counted in
    the round's level as before, only not accepted."""
    for c in evals:
        if c.name in explained and c.significant and not c.veto:
            c.significant = False
            c.veto = explained[c.name]
            log(f"    {c.name}: {c.veto}")


@blas_threads(1)   # small BLAS calls: a second thread only waits for a busy core (dsp.blas_threads)
def select(ctx, terms, recs, fold_all, block_all, max_terms, rows, fc_hp, log, f_band=None):
    """Forward selection: per round every remaining term is evaluated (cross-validated, nested), the drive-side
    group discriminated, and the first significant candidate whose exact model improves each fold accepted;
    then the term is fitted on all settled samples and every context is re-derived by exact simulation.

    Returns
    -------
    (accepted, rounds, ctx_all, fctx)
        Accepted candidates in order, the evaluations of every round, the refined model's context on all data
        and per fold (the terms fitted on fold f only: the model whose held-out error on fold 1 - f is scored).
    """
    accepted, rounds, explained = [], [], {}
    candidates = [t for t in terms if t.applicable(ctx)]
    ctx_all, fctx = ctx, [ctx, ctx]
    span = ctx.y_span
    for _ in range(max_terms):
        groups = {a.term.group for a in accepted if a.term.group}
        todo = [t for t in candidates if t.name not in {a.name for a in accepted}
                and not (t.group and t.group in groups)]
        if not todo:
            break
        p_max = sg.ALPHA / max(len(todo), 1)
        es = [residual(fctx[0])]
        es.append(es[0] if fctx[1] is fctx[0] else residual(fctx[1]))
        evals = sorted((_evaluate(fctx, t, es, fold_all, block_all, rows, p_max, _ratio_max(t, accepted),
                                  _beside_drive(accepted))
                        for t in todo), key=lambda c: c.ratio)
        for c in evals:
            c.selection_round = len(accepted) + 1
        evals = _lag_beyond_latency(evals, fctx, es, fold_all, block_all, rows, p_max, accepted, log)   # round 21
        creep_on_steps(evals, fctx, es, fold_all, block_all, rows, log)   # round 13: creep's test after the steps
        creep_model_on_dwells(evals, fctx, es, fold_all, block_all, rows, log)   # round 19: its model on the dwells
        drift_on_pair(evals, fctx, es, [slow_nuisance(c) for c in fctx], fold_all, block_all, rows, log)   # round 18
        drift_on_cycles(evals, fctx, es, fold_all, log)   # round 23: the cycle means on a repeated drive
        _discriminate(evals, fctx, fold_all, block_all, recs, fc_hp, log)
        _delay_or_pole(evals, ctx_all, f_band, log)   # round 20: the pair told apart by the magnitude
        _supersede(evals)
        if any(c.significant and not c.veto and c.name in SIGNATURES for c in evals):   # which slow term
            tests = signature_tests(fctx, es, [slow_nuisance(c) for c in fctx], fold_all, block_all, rows)
            log("    slow signatures: " + attribute(evals, tests))
            for t in tests:
                if t.level is not None:
                    log(f"    {t.name} level dependence: p {t.level['p']:.1e}, folds {t.level['fold_ratios'][0]:.3f}/"
                        f"{t.level['fold_ratios'][1]:.3f}" + (" (depends on the level)" if t.level["depends_on_level"] else ""))
            _slow_beyond_gates(evals, log)
        _coupling_motion(evals, fctx, es, fold_all, block_all, rows, log, bool(accepted))   # round 14 (25: on it)
        _veto_explained(evals, explained, log)   # round 22: a beyond-range pair already answered
        rounds.append(evals)
        check = None
        if f_band is not None:   # the drive-side terms' frequency-domain shape on the current model (signature.py)
            from .signature import check_in_context
            cache = {}
            check = (lambda c, _x=ctx_all, _k=cache: check_in_context(_x, c.name, _setting_of(c), f_band, _k,
                                                                      heldout=c.heldout))
        best = _first_exact(evals, fctx, fold_all, recs, span, log, check)
        log("  " + ", ".join(f"{c.name} {c.ratio:.3f} ({c.fold_ratios[0]:.2f}/{c.fold_ratios[1]:.2f} p {c.p:.0e} "
                             f"n{c.n_active} c{c.credited:.2f}){'*' if c.significant and not c.veto else ''}{'V' if c.veto else ''}"
                             for c in evals[:6]))
        while best is not None:   # round 27: a map of the reading after a slow term that explains more
            best = _slow_before_map(best, evals, fctx, fold_all, recs, span, log, check)
            best = _prefer_containing(best, evals, fctx, es, fold_all, block_all, rows, recs, span, log, check)
            best.veto = _map_within_slow(best)
            if best.veto is None:
                break
            log(f"    {best.name}: {best.veto}")
            best = _first_exact(evals, fctx, fold_all, recs, span, log, check)
        if best is None:
            break
        explained.update(_explained_beyond(best, evals))
        # setting and coefficients on all selection samples, applied to the all-data model
        allmask = fold_all >= 0
        e_all = residual(ctx_all)
        term = best.term
        # round 19: a term whose model is fitted with its own columns alone (round 17, ``Term.fit_model_alone``) is
        # so fitted on all data too: fitted beside the nested nuisance and simulated without it, the rate term's
        # all-data model was worse than the base on the data it was fitted to (null s117-023: NRMSE 0.0034 ->
        # 0.0067; rate s121-035: 0.0097 -> 0.0133) while its fold models, fitted alone, lowered the held-out error
        N = None if term.fit_model_alone(ctx_all) else _nuis(ctx_all, term, allmask, np.zeros(e_all.size, bool), rows,
                                                              dynamics=False, initial=False, accepted=False)
        st, _, _, _, th = best_setting(ctx_all, term, e_all, allmask, np.zeros(e_all.size, bool), rows, N)
        if best.from_dwells:   # round 19: the model the exact check passed, sized on every dwell
            th_d = creep_coef_on_dwells(ctx_all, e_all, allmask, rows)
            th = th if th_d is None else th_d
        if best.from_cycles:   # round 25: the drift sized on the repeated drive's cycles, on every training row
            sized = drift_coef_on_cycles(ctx_all, e_all, allmask)
            st, th = (st, th) if sized is None else sized
        best.setting_all, best.coef_all = st, th
        best.described = term.describe(ctx_all, st, th)
        c_term = np.array(th, float)
        c_term[term.nuisance_columns(ctx_all, c_term.size)] = 0.0  # where the term acts: its own columns only
        best.contrib = [np.asarray(term.regressors(ctx_all, s, st), float) @ c_term for s in ctx_all.signals]
        flex = [accepted_flexibility(fctx[f], term, best.setting[f]) for f in (0, 1)]   # on the model without it
        ctx_all = rebase(ctx_all, model_with(ctx_all.base, {term.name: term.term(ctx_all, st, th)}), recs)
        fctx = [rebase(fctx[f], best.exact[f]["params"], recs) for f in (0, 1)]
        for f in (0, 1):
            prev = fctx[f].accepted_flex
            fctx[f].accepted_flex = flex[f] if prev is None else np.hstack([prev, flex[f]])
        accepted.append(best)
    clear_output_cache()   # the drive-side settings' H outputs (up to 380 MB) serve the selection only
    return accepted, rounds, ctx_all, fctx
