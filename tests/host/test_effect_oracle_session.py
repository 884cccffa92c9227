"""bench.effect_oracle.model_error (round 28): a model is run on the recording's session clock, as ``diagnose``
runs it, so a drift on that clock continues from one recording to the next instead of restarting with each."""

import types

import numpy as np

from piezoctl.bench import effect_oracle as eo
from piezoctl.ident import refined


def _rec(start):
    t = np.arange(0.0, 2.0, 1e-3)
    meta = {} if start is None else {"session_time_s": start}
    return types.SimpleNamespace(t=t, u=np.zeros(t.size), u2=None, y=0.01 * (t + (start or 0.0)), meta=meta)


def test_the_model_runs_on_the_session_clock(monkeypatch):
    # a stand-in model: a drift of 0.01 um/s on the session clock (0 before the recording's start when none)
    monkeypatch.setattr(refined, "simulate",
                        lambda params, t, u, u2=None, t_session=None: 0.01 * (t + (t_session or 0.0)))
    late = _rec(30.0)   # the reading has drifted by 0.3 um when the recording starts 30 s into the session
    assert np.max(np.abs(eo.model_error({}, late))) < 1e-12
    # without the session clock the same model would leave the drift's 0.3 um level
    assert np.allclose(late.y - refined.simulate({}, late.t, late.u), 0.3)
    assert np.max(np.abs(eo.model_error({}, _rec(None)))) < 1e-12   # no session time: the recording's own clock
