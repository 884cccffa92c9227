"""A nested fit not determined by its training rows is refused, not crashed on (round 17, held-out s120-031)."""
import numpy as np

from piezoctl.diagnose.select import UNIDENTIFIED_GAIN, _fit_predict, _unidentified


def test_an_ordinary_fold_is_not_flagged():
    rng = np.random.default_rng(3)
    e = rng.normal(0.0, 0.05, 4000)
    assert _unidentified(e, e - 0.5 * e, 0.3 * e) is None
    # a residual made of a few bursts (a ringing after edges) is not a blow-up: the RMS, not the peak, is compared
    burst = np.zeros(4000)
    burst[::500] = 5.0
    assert _unidentified(burst, burst, burst) is None


def test_a_column_that_moves_only_on_held_out_rows_is_flagged():
    # a column that barely moves on the training rows and moves on the held-out ones: its coefficient is unbounded
    n = 2000
    rng = np.random.default_rng(4)
    e = rng.normal(0.0, 0.05, n)
    train = np.zeros(n, bool)
    train[: n // 2] = True
    test = ~train
    col = np.where(train, 1e-12 * rng.normal(size=n), 1.0)
    X = np.column_stack([col, rng.normal(size=n)])
    _, pred, _ = _fit_predict(X, e, train, test, rows=n)
    why = _unidentified(e[test], e[test], pred)
    assert why is not None and "not determined" in why
    assert float(np.sqrt(np.mean(pred ** 2))) > UNIDENTIFIED_GAIN * float(np.sqrt(np.mean(e[test] ** 2)))


def test_non_finite_predictions_are_flagged():
    e = np.full(100, 0.1)
    assert _unidentified(e, e, np.full(100, np.inf)) is not None
    assert _unidentified(e, np.full(100, np.nan), e) is not None
