"""Compiled 4-state Kalman steps of :mod:`demtrack.core.tracking.kalman`.

A live tracker predicts every track at each scan and updates and smooths the ones that
take a fix: thousands of 4 x 4 products a second. As numpy calls each product cost more
in call overhead than in arithmetic; these kernels do each step in one call. Plain-numpy
twins (the forms they replaced) are in :mod:`demtrack.core.tracking.kalman_reference`;
the tests compare them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["predict_kernel", "rts_positions_kernel", "smoother_gain_kernel", "update_kernel"]


@njit(cache=True)
def predict_kernel(x, p, f, q):  # pragma: no cover - numba
    """``(F x, sym(F P F^T + Q))`` for state ``x`` (4,), covariance ``p`` (4, 4)."""
    x_new = f @ x
    p_new = f @ p @ f.T + q
    return x_new, 0.5 * (p_new + p_new.T)


@njit(cache=True)
def update_kernel(x, p, z_xy, r):  # pragma: no cover - numba
    """Linear update with a position ``z_xy`` (2,) of covariance ``r`` (2, 2), Joseph form.

    The innovation covariance is inverted in closed form; returns ``(x, sym(P))``.
    """
    s00 = p[0, 0] + r[0, 0]
    s01 = p[0, 1] + r[0, 1]
    s10 = p[1, 0] + r[1, 0]
    s11 = p[1, 1] + r[1, 1]
    det = s00 * s11 - s01 * s10
    i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
    k = np.empty((4, 2))
    for a in range(4):  # K = P H^T S^-1 (S symmetric up to round-off: as the numpy form)
        k[a, 0] = i00 * p[0, a] + i01 * p[1, a]
        k[a, 1] = i10 * p[0, a] + i11 * p[1, a]
    nu0 = z_xy[0] - x[0]
    nu1 = z_xy[1] - x[1]
    x_new = np.empty(4)
    for a in range(4):
        x_new[a] = x[a] + k[a, 0] * nu0 + k[a, 1] * nu1
    ikh = np.eye(4)
    for a in range(4):
        ikh[a, 0] -= k[a, 0]
        ikh[a, 1] -= k[a, 1]
    p_new = ikh @ p @ ikh.T + k @ r @ k.T
    return x_new, 0.5 * (p_new + p_new.T)


@njit(cache=True)
def smoother_gain_kernel(p_k, f, q):  # pragma: no cover - numba
    """Rauch-Tung-Striebel gain ``G = P_k F^T (F P_k F^T + Q)^-1`` (4, 4)."""
    p_pred = f @ p_k @ f.T + q
    return np.linalg.solve(p_pred, f @ p_k).T


@njit(cache=True)
def rts_positions_kernel(xs, fs, gains):  # pragma: no cover - numba
    """Smoothed horizontal positions (n, 2) from filtered means ``xs`` (n, 4).

    ``fs``/``gains`` (n - 1, 4, 4): the transition and gain from each entry but the
    newest to the next. The newest position is the filtered one.
    """
    n = xs.shape[0]
    out = np.empty((n, 2))
    s = xs[n - 1].copy()
    out[n - 1] = s[:2]
    for k in range(n - 2, -1, -1):
        s = xs[k] + gains[k] @ (s - fs[k] @ xs[k])
        out[k] = s[:2]
    return out
