"""The Bouc-Wen column of exponent n != 1 (models/hysteresis.py, ``bouc_wen_h(..., n)``): its tabulated run
solution against the closed form at n = 1 and against a direct integration of the law at other exponents."""

import numpy as np
import pytest

from piezoctl.models.hysteresis import _bouc_wen_h, _bouc_wen_h_n, bouc_wen_h, hysteresis_parts


def _drive(seed, n=20_000):
    rng = np.random.default_rng(seed)
    return 0.9 * np.sin(np.cumsum(rng.normal(0, 0.01, n))) * np.linspace(1.0, 0.4, n)


@pytest.mark.parametrize("beta,gamma,f0", [(3.0, 1.0, 0.0), (10.0, -4.0, -0.8), (1.0, 0.5, 0.6)])
def test_table_at_exponent_one_equals_the_closed_form(beta, gamma, f0):
    v = _drive(0)
    hu = 1.0 / (beta + gamma)
    exact = _bouc_wen_h(v, beta, gamma, 0.2, f0 * hu)
    assert np.max(np.abs(_bouc_wen_h_n(v, beta, gamma, 0.2, 1.0, f0 * hu) - exact)) < 1e-4 * hu


def _rk4(v, beta, gamma, n, v_rest, h0=0.0, sub=20):
    """Per-sample RK4 of dh/dv = 1 - |h|^n (beta sign(h dv) + gamma), ``sub`` steps per drive step."""
    h, out, prev = h0, np.empty(v.size), v_rest
    for k, x in enumerate(v):
        dv = (x - prev) / sub
        s = 1.0 if dv > 0 else -1.0

        def g(z):
            return 1.0 - abs(z) ** n * (beta * np.sign(z * s) + gamma)
        for _ in range(sub):
            k1 = g(h); k2 = g(h + dv / 2 * k1); k3 = g(h + dv / 2 * k2); k4 = g(h + dv * k3)
            h += dv / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[k], prev = h, x
    return out


@pytest.mark.parametrize("n,f0", [(0.6, 0.0), (1.7, -0.7), (3.0, 0.5)])
def test_exponent_n_follows_the_law_integrated_step_by_step(n, f0):
    v = _drive(1, 3000)
    beta, gamma = 2.0, -0.6
    hu = (beta + gamma) ** (-1.0 / n)
    ref = _rk4(v, beta, gamma, n, -0.3, f0 * hu)
    got = bouc_wen_h(v, beta, gamma, -0.3, n, f0 * hu)
    assert np.max(np.abs(got - ref)) < 1e-3 * hu
    assert np.max(np.abs(got - ref)) < 0.01 * np.std(ref)


def test_rate_independent_a_refined_drive_path_gives_the_same_states():
    v = _drive(2, 4000)
    fine = np.interp(np.arange(4 * v.size - 3) / 4.0, np.arange(v.size), v)   # three points inserted per step
    a = _bouc_wen_h_n(v, 1.5, 0.3, 0.0, 2.2)
    b = _bouc_wen_h_n(fine, 1.5, 0.3, 0.0, 2.2)[::4]
    assert np.max(np.abs(a - b)) < 1e-9


def test_plane_with_an_exponent_n_column_uses_it():
    v = _drive(3, 3000)
    hp = {"type": "plane", "r": [0.0], "knots": [[-1.0, 0.0, 1.0]], "values": [[0.0, 1.0, 2.0]], "offset": 0.0,
          "v_rest": 0.0, "v_lo": -1.0, "v_hi": 1.0, "bw": {"beta": 2.0, "gamma": 0.4, "n": 2.0, "c_h": 1.5}}
    h, hyst = hysteresis_parts(hp, v)
    h1, _ = hysteresis_parts({**hp, "bw": {"beta": 2.0, "gamma": 0.4, "c_h": 1.5}}, v)   # n absent: 1
    assert np.allclose(h - h1, 1.5 * (_bouc_wen_h_n(v, 2.0, 0.4, 0.0, 2.0) - _bouc_wen_h(v, 2.0, 0.4, 0.0)))


def test_groups_of_a_plane_with_an_exponent_n_column_sum_to_its_output():
    """The nested tests' nuisance (``hysteresis_groups``) refits the base's own groups: with an exponent n != 1
    the Bouc-Wen group must be the model's own column (it was the n = 1 column, so the groups did not sum to H)."""
    from piezoctl.models.hysteresis import hysteresis_groups
    v = _drive(4, 3000)
    hp = {"type": "plane", "r": [0.0, 0.5], "knots": [[-1.0, 0.0, 1.0], [-0.5, 0.5]],
          "values": [[0.0, 1.0, 2.0], [0.0, 0.3]], "offset": 0.0, "v_rest": 0.0, "v_lo": -1.0, "v_hi": 1.0,
          "bw": {"beta": 2.0, "gamma": 0.4, "n": 2.5, "h0": 0.1, "c_h": 1.5}}
    h, _ = hysteresis_parts(hp, v)
    G = hysteresis_groups(hp, v)
    assert G.shape[1] == 3
    assert np.allclose(G[:, 2], 1.5 * bouc_wen_h(v, 2.0, 0.4, 0.0, 2.5, 0.1))
    assert np.allclose(G.sum(axis=1), h - np.mean(h - G.sum(axis=1)))
