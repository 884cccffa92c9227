"""One check of two base fits being the same, for the speed tests whose changes must keep every float."""

import numpy as np

from piezoctl.ident import base as B


def assert_same_base(new, old):
    """Assert two ``fit_base(..., holdout=True)`` results equal: every parameter (the cross-validation table
    included) and every held-out history, array for array, bit for bit."""
    ho_new, ho_old = B.history_holdout(new), B.history_holdout(old)
    assert new == old
    assert len(ho_new) == len(ho_old) > 0
    for hn, ho in zip(ho_new, ho_old):
        assert hn.keys() == ho.keys()
        for k in hn:
            assert np.array_equal(np.asarray(hn[k]), np.asarray(ho[k]))
