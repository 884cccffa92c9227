"""Discrete Laguerre filter bank in state space (for the distributed Hammerstein model).

The ``m`` filters :math:`L_1(z^{-1}) \\dots L_m(z^{-1})` are the states of

.. math::

    \\zeta(t+1) = A\\,\\zeta(t) + B\\,\\mu(t), \\qquad L_i(z^{-1})[\\mu](t) = \\zeta_i(t),

with :math:`A` lower-triangular Toeplitz: :math:`\\rho_1` on the diagonal and, for
:math:`i > j`, :math:`A_{ij} = (-1)^{i-j-1}\\rho_2^{\\,i-j-1}(\\rho_1\\rho_2 + \\rho_3)/T^{\\,i-j}`;
:math:`B = \\rho_4 [1, -\\rho_2/T, \\dots, (-\\rho_2/T)^{m-1}]^T`, where

.. math::

    \\rho_1 = e^{-qT},\\quad \\rho_2 = T + \\tfrac{2}{q}(\\rho_1 - 1),\\quad
    \\rho_3 = -T\\rho_1 - \\tfrac{2}{q}(\\rho_1 - 1),\\quad
    \\rho_4 = \\sqrt{2q}\\,(1 - \\rho_1)/q.

``q`` is the continuous Laguerre pole [1/sample-time unit] and ``T`` the sampling
interval in the same time unit (the paper uses q = 0.1, T = 2; only the product
``qT`` and ``T`` enter). The filter outputs are the states at time t (one sample of
delay: the filters are strictly proper).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = ["laguerre_rhos", "laguerre_ab", "laguerre_filter"]


def laguerre_rhos(q: float, T: float) -> tuple[float, float, float, float]:
    """(rho1, rho2, rho3, rho4) of the discretized Laguerre network.

    Parameters
    ----------
    q : float
        Laguerre pole, > 0 [1/time unit].
    T : float
        Sampling interval, > 0 [time unit].
    """
    if not (q > 0 and T > 0):
        raise ValueError(f"Laguerre parameters must be positive (q={q}, T={T})")
    r1 = math.exp(-q * T)
    r2 = T + 2.0 / q * (r1 - 1.0)
    r3 = -T * r1 - 2.0 / q * (r1 - 1.0)
    r4 = math.sqrt(2.0 * q) * (1.0 - r1) / q
    return r1, r2, r3, r4


def laguerre_ab(m: int, q: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """State matrix A (m x m) and input vector B (m,) of ``m`` Laguerre filters.

    Parameters
    ----------
    m : int
        Number of filters, >= 1.
    q, T : float
        See :func:`laguerre_rhos`.
    """
    if int(m) != m or m < 1:
        raise ValueError(f"number of Laguerre filters must be an integer >= 1 (got {m})")
    m = int(m)
    r1, r2, r3, r4 = laguerre_rhos(q, T)
    col = np.empty(m)
    col[0] = r1
    for k in range(1, m):  # k = i - j
        col[k] = (-1.0) ** (k - 1) * r2 ** (k - 1) * (r1 * r2 + r3) / T ** k
    a = np.zeros((m, m))
    for i in range(m):
        a[i, : i + 1] = col[i::-1]
    b = r4 * (-r2 / T) ** np.arange(m)
    return a, b


def laguerre_filter(mu, m: int, q: float, T: float, steady: bool = True) -> np.ndarray:
    """Outputs of the ``m`` Laguerre filters for each input column.

    Parameters
    ----------
    mu : array_like, shape (N,) or (N, K)
        Input sequence(s), one per column.
    m : int
        Number of filters.
    q, T : float
        See :func:`laguerre_rhos`.
    steady : bool
        Start every filter at the equilibrium of the constant input ``mu[0]``
        (no start-up transient for a record that begins at an offset); else at 0.

    Returns
    -------
    ndarray, shape (N, m) or (N, m, K)
        ``out[t, i]`` is :math:`L_{i+1}(z^{-1})[\\mu](t) = \\zeta_{i+1}(t)`.
    """
    mu = np.asarray(mu, dtype=float)
    one = mu.ndim == 1
    x = mu[:, None] if one else mu
    a, b = laguerre_ab(m, q, T)
    out = np.empty((x.shape[0], m, x.shape[1]))
    for i in range(m):
        c = np.zeros((1, m))
        c[0, i] = 1.0
        num, den = signal.ss2tf(a, b[:, None], c, np.zeros((1, 1)))
        num = num[0]
        if steady:
            zi = signal.lfilter_zi(num, den)[:, None] * x[0][None, :]
            out[:, i, :] = signal.lfilter(num, den, x, axis=0, zi=zi)[0]
        else:
            out[:, i, :] = signal.lfilter(num, den, x, axis=0)
    return out[:, :, 0] if one else out
