"""The sensor curve's test on the branch-common part of the residual (round 19, diagnose/static_map.py)."""

import numpy as np

from piezoctl.diagnose.static_map import branch_common_test, branches


def _triangle(amps, n_half=400):
    """A drive of triangles of the given amplitudes [V] around 50 V, one cycle each, and its direction."""
    u, d = [], []
    for a in amps:
        up = np.linspace(50 - a, 50 + a, n_half)
        u += [up, up[::-1]]
        d += [np.ones(n_half), -np.ones(n_half)]
    return np.concatenate(u), np.concatenate(d)


def test_branches_turn_where_the_drive_turns_and_not_on_noise():
    u, _ = _triangle([40, 30, 20])
    b = branches(u)
    assert b.max() + 1 == 6   # three cycles, each rising then falling
    assert np.all(np.diff(b) >= 0)
    rng = np.random.default_rng(1)
    noisy = u + rng.normal(0, 0.05, u.size)   # 0.05 V against a 2 % play of an 80 V span
    assert branches(noisy).max() + 1 == 6
    steps = np.repeat([10, 30, 50, 70, 50, 30], 200).astype(float)   # a staircase up, then down
    bs = branches(steps)
    assert bs.max() + 1 == 2 and bs[0] == 0 and bs[-1] == 1   # dwells keep the branch that reached them


def _case(curve: bool, seed=0):
    """Triangles of several amplitudes; the residual is a history misfit (of opposite signs rising and falling, of
    a size that depends on the loop's amplitude) plus, when ``curve``, a static map of y smaller than it."""
    rng = np.random.default_rng(seed)
    amps = [40, 25, 35, 15, 30, 20, 38, 28]
    u, d = _triangle(amps)
    y = 0.5 * u                                   # [um]
    q = (y - y.mean()) / (0.5 * np.ptp(y))
    size = np.repeat([0.006 * a for a in amps], 800)   # the misfit grows with the loop [um]
    e = d * size * (1 - q ** 2) + rng.normal(0, 0.01, u.size)
    c = 0.15 * q ** 2 + 0.1 * q ** 3
    if curve:
        e = e + c - np.mean(c)
    X = np.column_stack([q ** 2, q ** 3, np.ones(u.size)])
    fold = (np.arange(u.size) // 1600) % 2        # alternate blocks of two cycles
    return y, branches(u), e, X, fold, c


def test_a_static_curve_beside_a_larger_history_misfit_passes_on_the_branch_common_part():
    y, b, e, X, fold, c = _case(curve=True)
    # the whole residual: the curve's least squares on one fold predicts the other no better than 0.8
    whole = []
    for f in (0, 1):
        th = np.linalg.lstsq(X[fold == f], e[fold == f], rcond=None)[0]
        t = fold == 1 - f
        whole.append(np.sqrt(np.mean((e[t] - X[t] @ th) ** 2) / np.mean(e[t] ** 2)))
    assert min(whole) > 0.8
    r = branch_common_test(y, b, e, X, None, fold)
    assert r is not None
    assert max(r["fold_ratios"]) < 0.5
    assert r["p"] < 1e-3
    assert r["after_um"] < 0.5 * r["before_um"]


def test_the_history_misfit_alone_is_not_a_curve_to_the_branch_common_test():
    y, b, e, X, fold, _ = _case(curve=False)
    r = branch_common_test(y, b, e, X, None, fold)
    assert r is not None
    assert not (max(r["fold_ratios"]) <= 0.8 and r["p"] < 1e-3)   # the first round's gates (p: 0.01 / 12)
    assert r["before_um"] < 0.2 * float(np.std(e))   # the misfit, 0.14 um RMS, averages out across branches


def test_too_few_bins_for_the_columns_is_no_test():
    y, b, e, X, fold, _ = _case(curve=True)
    N = np.random.default_rng(2).normal(size=(y.size, 30))   # more nuisance columns than bins
    assert branch_common_test(y, b, e, X, N, fold) is None


def test_the_evidence_says_the_figures_are_the_branch_common_parts_and_gives_the_whole_residuals():
    from piezoctl.diagnose.run import _branch_common_text
    y, b, e, X, fold, _ = _case(curve=True)
    bc = branch_common_test(y, b, e, X, None, fold)
    bc["credited_ratio"] = 0.35
    text = _branch_common_text({"branch_common": bc, "fold_ratios": [0.76, 0.80], "p": 1.8e-2, "credited_ratio": 0.86})
    assert "every branch shares at equal displacement" in text
    assert f"{bc['n_bins']} held-out bins" in text and "did not see, 0.35" in text
    assert "0.76/0.80, p = 1.8e-02, credited ratio 0.86" in text


def test_a_map_common_to_one_recordings_branches_does_not_carry_to_the_others():
    from piezoctl.diagnose.static_map import across_recordings
    y, b, e, X, fold, c = _case(curve=True)
    rec = np.repeat([0, 1, 2, 3], y.size // 4)   # two cycles per "recording"
    q = X[:, 0] ** 0.5 * np.sign(X[:, 1])
    r = across_recordings(y, b, rec, e, X)
    assert len(r) == 4 and max(r.values()) < 1.0   # the sensor's curve: the others' map lowers each one's
    # a misfit the same at equal y on the branches of recording 0 only (an even loop-shape error of its history)
    e_one = np.where(rec == 0, 0.15 * (1 - q ** 2), 0.0) + np.random.default_rng(3).normal(0, 0.01, y.size)
    r1 = across_recordings(y, b, rec, e_one, X)
    assert max(r1.values()) > 1.0   # not the same map everywhere: the others predict recording 0 wrongly or it them


def test_the_common_parts_coefficients_are_the_maps_where_long_dwells_carry_the_misfit():
    """Round 20: a recording of long dwells whose misfit follows the level (a history the calibration did not show)
    pulls the whole residual's least squares towards it, sample by sample; the common part counts each branch's
    mean once per bin, and its per-fold coefficients stay near the map's (held-out s124-026's steps)."""
    rng = np.random.default_rng(3)
    amps = [40, 25, 35, 15, 30, 20, 38, 28]
    u_t, d_t = _triangle(amps)
    levels = np.array([12, 24, 36, 48, 60, 72, 84, 72, 60, 48, 36, 24, 12], float)
    u_s = np.repeat(levels, 1200)                       # a staircase up and down, 1200 samples per dwell
    u = np.concatenate([u_t, u_s])
    y = 0.5 * u
    q = (y - 25.0) / 20.0
    mis = np.concatenate([d_t * 0.05 * (1 - q[:u_t.size] ** 2),           # odd in the direction on the triangles
                          0.4 * (q[u_t.size:] ** 2 - 0.3) * (u_s < 50)])   # the dwells: one-sided, by level
    c2, c3 = 0.15, 0.1
    e = mis + c2 * q ** 2 + c3 * q ** 3 + rng.normal(0, 0.01, u.size)
    X = np.column_stack([q ** 2, q ** 3, np.ones(u.size)])
    fold = (np.arange(u.size) // 1600) % 2
    r = branch_common_test(y, branches(u), e, X, None, fold)
    assert r is not None and len(r["coef"]) == 2
    for f in (0, 1):
        whole = np.linalg.lstsq(X[fold == f], e[fold == f], rcond=None)[0]
        common = np.asarray(r["coef"][f])
        assert abs(common[0] - c2) < 0.5 * abs(whole[0] - c2)
        assert abs(common[0] - c2) < 0.05


def test_the_curves_test_nuisance_is_the_dynamics_corrections_and_the_common_route_leaves_it_out():
    """Round 20: the curve is fitted beside free ``c1 s + c2 s^2`` corrections of G in its nested test (a map of the
    reading is the same at every rate); the branch-common route's nuisance leaves them out (their common part is
    near zero)."""
    from types import SimpleNamespace
    from piezoctl.diagnose.select import term_nuisance
    from piezoctl.ident.terms import TERMS
    t = np.arange(500) * 1e-3
    sig = [SimpleNamespace(ydyn=np.sin(2 * np.pi * 7 * t)), SimpleNamespace(ydyn=np.cos(2 * np.pi * 3 * t))]
    valid = [np.arange(500) >= 20, np.arange(500) >= 50]
    ctx = SimpleNamespace(signals=sig, valid=valid, dyn_nuisance=None, dyn_nuisance_above=None, accepted_flex=None,
                          nuisance=None)

    class Unnested(type(TERMS["sensor_nonlinearity"])):
        nested = False   # the hysteresis groups need a base; the test nuisance alone here

    term = Unnested()
    N = term.test_nuisance(ctx)
    assert N.shape == (480 + 450, 2)
    d1 = np.diff(sig[0].ydyn, prepend=sig[0].ydyn[0])   # the first and second differences of the dynamic output
    d2 = np.diff(d1, prepend=d1[0])
    assert np.allclose(N[:480, 0], d1[valid[0]]) and np.allclose(N[:480, 1], d2[valid[0]])
    assert np.array_equal(term_nuisance(ctx, term), N)
    assert term_nuisance(ctx, term, own_test=False) is None
    ctx.accepted_flex = np.zeros((930, 1))   # after a term: first round only (the own rate case's false curve)
    assert term.test_nuisance(ctx) is None

def _dense_averager(ybin, branch, n_bins):
    """The averager as a dense (bins x samples) matrix, cell by cell (round 19's form): the reference."""
    from piezoctl.diagnose.static_map import MIN_BRANCHES, MIN_CELL
    rows, w = [], []
    for k in range(n_bins):
        cells = [(b, np.flatnonzero((branch == b) & (ybin == k))) for b in np.unique(branch)]
        cells = [s for _, s in cells if s.size >= MIN_CELL]
        if len(cells) < MIN_BRANCHES:
            continue
        r = np.zeros(ybin.size)
        for s in cells:
            r[s] = 1.0 / (s.size * len(cells))
        rows.append(r)
        w.append(len(cells))
    return np.array(rows).reshape(len(rows), ybin.size), np.array(w, float)


def test_the_sparse_averager_is_the_dense_one_on_random_cells():
    from piezoctl.diagnose.static_map import common_averager
    rng = np.random.default_rng(4)
    for trial in range(40):
        n = int(rng.integers(0, 3000))
        n_bins = int(rng.integers(1, 30))
        # runs of branches (non-decreasing, as branches() gives, or shuffled) over bins of varied sizes
        branch = np.sort(rng.integers(0, int(rng.integers(1, 60)), n))
        if trial % 3 == 0:
            branch = rng.permutation(branch)
        ybin = rng.integers(0, n_bins, n)
        A, w = common_averager(ybin, branch, n_bins)
        D, wd = _dense_averager(ybin, branch, n_bins)
        assert A.shape == D.shape and np.array_equal(w, wd)
        assert np.array_equal(A.toarray(), D)   # the same weights, bit for bit
        assert np.all(A.getnnz(axis=0) <= 1)     # one entry per sample at most
        X = rng.normal(size=(n, 3))
        assert np.allclose(A @ X, D @ X, rtol=1e-12, atol=1e-15)
        assert (A @ X[:, :0]).shape == (D.shape[0], 0)


def test_the_sparse_averager_gives_the_dense_ones_figures_on_the_curve_case():
    from piezoctl.diagnose import static_map
    y, b, e, X, fold, _ = _case(curve=True)
    new = branch_common_test(y, b, e, X, None, fold)
    rec = np.repeat([0, 1, 2, 3], y.size // 4)
    new_rec = static_map.across_recordings(y, b, rec, e, X)
    keep = static_map.common_averager
    try:
        static_map.common_averager = lambda yb, br, n_bins=static_map.N_BINS: _dense_averager(yb, br, n_bins)
        old = branch_common_test(y, b, e, X, None, fold)
        old_rec = static_map.across_recordings(y, b, rec, e, X)
    finally:
        static_map.common_averager = keep
    assert new["n_bins"] == old["n_bins"] > 0
    for k in ("p", "before_um", "after_um"):
        assert np.isclose(new[k], old[k], rtol=1e-10, atol=0)
    assert np.allclose(new["fold_ratios"], old["fold_ratios"], rtol=1e-10, atol=0)
    assert new_rec.keys() == old_rec.keys() and np.allclose(list(new_rec.values()), list(old_rec.values()),
                                                            rtol=1e-10, atol=0)


def _history(resid, resid_in, u, y, rec=0, segment=0):
    """One held-out calibration history covering the whole of recording ``rec``, every sample scored."""
    return {"recording": rec, "segment": segment, "start": 0, "stop": u.size, "resid": resid, "resid_in": resid_in,
            "scored": np.ones(u.size, bool)}


def test_the_bases_lag_misfit_leaves_little_in_the_common_part_and_a_level_keeps_its_energy():
    # round 26: a lag of the model behind the stage (opposite sign rising and falling at equal y) averages out of
    # the branch-common part; a level (an unknown initial state) is common to every branch and keeps its energy
    from piezoctl.diagnose.static_map import common_misfit
    rng = np.random.default_rng(3)
    u, d = _triangle([40, 30, 35, 20, 38, 25])
    y = 0.5 * u
    seen = rng.normal(0, 0.01, u.size)   # the reference fit's error on the same samples: noise [um]
    lag = seen + 0.08 * d
    m_lag = common_misfit([_history(lag, seen, u, y)], [u], [y])
    assert m_lag is not None and m_lag < 0.05 * float(np.mean(lag ** 2) - np.mean(seen ** 2))
    level = seen + 0.08
    m_level = common_misfit([_history(level, seen, u, y)], [u], [y])
    assert abs(m_level - 0.08 ** 2) < 0.1 * 0.08 ** 2
    # held out no worse than seen: no excess
    assert common_misfit([_history(seen, seen, u, y)], [u], [y]) == 0.0


def test_a_history_too_short_for_two_bins_gives_no_common_misfit_and_the_credit_falls_back_to_the_whole():
    from piezoctl.diagnose.select import common_misfit_um2
    from piezoctl.diagnose.static_map import common_misfit
    u = np.linspace(0.0, 10.0, 60)   # one branch, fewer samples than the bins need
    h = _history(np.full(u.size, 0.1), np.zeros(u.size), u, 0.5 * u)
    assert common_misfit([h], [u], [0.5 * u]) is None
    mse = {"level": 0.01, "slow": 0.002, "fast": 0.003}
    assert common_misfit_um2({"mse_um2": mse, "common_um2": None}) == sum(mse.values())
    assert common_misfit_um2({"mse_um2": mse, "common_um2": 0.001}) == 0.001
    assert common_misfit_um2(None) == 0.0


def test_the_levels_of_one_refits_histories_average_as_the_recordings_do_and_separate_refits_keep_theirs():
    # one refit predicting two histories it did not see, off by opposite levels, is one model on two recordings:
    # their common part averages the levels where both visit; two refits' histories are reduced apart
    from piezoctl.diagnose.static_map import common_misfit
    u, _ = _triangle([40, 30, 35, 20, 38, 25])
    y, z = 0.5 * u, np.zeros(u.size)
    up, down = _history(z + 0.08, z, u, y, rec=0), _history(z - 0.08, z, u, y, rec=1)
    assert common_misfit([up, down], [u, u], [y, y]) < 1e-3 * 0.08 ** 2   # against 0.08 ** 2 apart
    down["segment"] = 1
    assert abs(common_misfit([up, down], [u, u], [y, y]) - 0.08 ** 2) < 1e-9
