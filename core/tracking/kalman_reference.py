"""Plain-numpy twins of :mod:`demtrack.core.tracking.kalman_kernels` (for the tests)."""

from __future__ import annotations

import numpy as np

__all__ = [
    "predict_reference",
    "rts_positions_reference",
    "smoother_gain_reference",
    "update_reference",
]

_H = np.hstack([np.eye(2), np.zeros((2, 2))])


def predict_reference(x, p, f, q):
    """:func:`~demtrack.core.tracking.kalman_kernels.predict_kernel` in numpy."""
    p_new = f @ p @ f.T + q
    return f @ x, 0.5 * (p_new + p_new.T)


def update_reference(x, p, z_xy, r):
    """:func:`~demtrack.core.tracking.kalman_kernels.update_kernel` in numpy."""
    s = p[:2, :2] + r
    det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    s_inv = np.array([[s[1, 1], -s[0, 1]], [-s[1, 0], s[0, 0]]]) / det
    k = (s_inv @ p[:2, :]).T
    x_new = x + k @ (z_xy - x[:2])
    ikh = np.eye(4) - k @ _H
    p_new = ikh @ p @ ikh.T + k @ r @ k.T
    return x_new, 0.5 * (p_new + p_new.T)


def smoother_gain_reference(p_k, f, q):
    """:func:`~demtrack.core.tracking.kalman_kernels.smoother_gain_kernel` in numpy."""
    p_pred = f @ p_k @ f.T + q
    return np.linalg.solve(p_pred, f @ p_k).T


def rts_positions_reference(xs, fs, gains):
    """:func:`~demtrack.core.tracking.kalman_kernels.rts_positions_kernel` in numpy."""
    s = xs[-1]
    out = [s[:2].copy()]
    for k in range(len(xs) - 2, -1, -1):
        s = xs[k] + gains[k] @ (s - fs[k] @ xs[k])
        out.append(s[:2].copy())
    return np.array(out[::-1])
