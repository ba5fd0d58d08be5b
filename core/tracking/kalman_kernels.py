"""Compiled 4-state Kalman steps of :mod:`demtrack.core.tracking.kalman`.

A live tracker predicts every track at each scan and updates and smooths the ones that
take a fix: thousands of 4 x 4 products a second. As numpy calls each product cost more
in call overhead than in arithmetic; these kernels do each step in one call. Plain-numpy
twins (the forms they replaced) are in :mod:`demtrack.core.tracking.reference`;
the tests compare them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["predict_kernel", "rts_positions_kernel", "smoother_gain_kernel", "update_kernel"]


# numpy's ``@`` and ``np.linalg.solve`` inside numba bind BLAS/LAPACK and took some 20 s
# of CPU to compile cold (a cold console's first tracks waited for it); 4 x 4 loops compile
# in well under a second each and are as fast on these sizes.


@njit(cache=True, inline="always")
def _abt(a, b, transpose_b):  # pragma: no cover - numba
    """``a @ b`` (or ``a @ b.T``) for small 2-D arrays."""
    n, m = a.shape[0], a.shape[1]
    k = b.shape[0] if transpose_b else b.shape[1]
    out = np.zeros((n, k))
    for i in range(n):
        for j in range(k):
            acc = 0.0
            for r in range(m):
                acc += a[i, r] * (b[j, r] if transpose_b else b[r, j])
            out[i, j] = acc
    return out


@njit(cache=True, inline="always")
def _sandwich(f, p, q):  # pragma: no cover - numba
    """``sym(F P F^T + Q)`` (each (4, 4))."""
    out = _abt(_abt(f, p, False), f, True)
    for i in range(4):
        for j in range(4):
            out[i, j] += q[i, j]
    return _symmetric(out)


@njit(cache=True, inline="always")
def _symmetric(a):  # pragma: no cover - numba
    """``0.5 (A + A^T)`` of a square array, as a new array."""
    n = a.shape[0]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.5 * (a[i, j] + a[j, i])
    return out


@njit(cache=True)
def predict_kernel(x, p, f, q):  # pragma: no cover - numba
    """``(F x, sym(F P F^T + Q))`` for state ``x`` (4,), covariance ``p`` (4, 4)."""
    x_new = np.zeros(4)
    for i in range(4):
        for j in range(4):
            x_new[i] += f[i, j] * x[j]
    return x_new, _sandwich(f, p, q)


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
    p_new = _abt(_abt(ikh, p, False), ikh, True)
    krk = _abt(_abt(k, r, False), k, True)
    for i in range(4):
        for j in range(4):
            p_new[i, j] += krk[i, j]
    return x_new, _symmetric(p_new)


@njit(cache=True)
def smoother_gain_kernel(p_k, f, q):  # pragma: no cover - numba
    """Rauch-Tung-Striebel gain ``G = P_k F^T (F P_k F^T + Q)^-1`` (4, 4).

    ``G^T`` solves ``P_pred G^T = F P_k`` (``P_pred`` symmetric): Gaussian elimination
    with partial pivoting on the 4 x 4 system and its four right-hand sides.
    """
    a = _abt(_abt(f, p_k, False), f, True)
    for i in range(4):
        for j in range(4):
            a[i, j] += q[i, j]
    b = _abt(f, p_k, False)
    for c in range(4):
        piv = c
        for r in range(c + 1, 4):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if piv != c:
            for j in range(4):
                a[c, j], a[piv, j] = a[piv, j], a[c, j]
                b[c, j], b[piv, j] = b[piv, j], b[c, j]
        for r in range(c + 1, 4):
            m = a[r, c] / a[c, c]
            for j in range(c, 4):
                a[r, j] -= m * a[c, j]
            for j in range(4):
                b[r, j] -= m * b[c, j]
    gain = np.empty((4, 4))  # G = (G^T)^T, back substitution column by column
    for c in range(3, -1, -1):
        for j in range(4):
            acc = b[c, j]
            for r in range(c + 1, 4):
                acc -= a[c, r] * gain[j, r]
            gain[j, c] = acc / a[c, c]
    return gain


@njit(cache=True)
def rts_positions_kernel(xs, fs, gains):  # pragma: no cover - numba
    """Smoothed horizontal positions (n, 2) from filtered means ``xs`` (n, 4).

    ``fs``/``gains`` (n - 1, 4, 4): the transition and gain from each entry but the
    newest to the next. The newest position is the filtered one.
    """
    n = xs.shape[0]
    out = np.empty((n, 2))
    s = np.empty(4)
    d = np.empty(4)
    for i in range(4):
        s[i] = xs[n - 1, i]
    for k in range(n - 1, -1, -1):
        if k < n - 1:
            for i in range(4):
                acc = 0.0
                for j in range(4):
                    acc += fs[k, i, j] * xs[k, j]
                d[i] = s[i] - acc
            for i in range(4):
                acc = xs[k, i]
                for j in range(4):
                    acc += gains[k, i, j] * d[j]
                s[i] = acc
        out[k, 0] = s[0]
        out[k, 1] = s[1]
    return out
