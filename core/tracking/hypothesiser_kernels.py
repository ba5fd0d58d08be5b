"""Compiled gating for :class:`~demtrack.core.tracking.hypothesiser.GatedNearestHit`.

A scan gates a handful of tracks against a handful of candidates; as numpy calls on
such tiny arrays the gating cost a dozen ufunc calls, a concatenation and fancy indexing
per scan, far more than its arithmetic. This kernel does it in one call with the same
operations in the same order (:func:`~demtrack.core.tracking.hypothesiser.mahalanobis2`'s
closed form, no fused multiply-add), so its distances equal the numpy ones to the last
bit. Its plain-numpy twin is
:func:`~demtrack.core.tracking.reference.gate_reference` (the form it replaced); the tests
compare them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["gate_kernel"]


# error_model="numpy": a singular covariance gives inf or NaN as numpy does, not an error
@njit(cache=True, error_model="numpy")
def gate_kernel(means_xy, covs_xy, z_xy, cov, slots, allowed):  # pragma: no cover - numba
    """Nearest candidate of every (track, measurement) pair and its squared distance.

    Parameters
    ----------
    means_xy : ndarray, shape (t, 2)
        Tracks' predicted horizontal positions (m).
    covs_xy : ndarray, shape (t, 2, 2)
        Their covariances (m^2).
    z_xy : ndarray, shape (c, 2)
        Stacked candidates' positions (m).
    cov : ndarray, shape (c, 2, 2)
        Their covariances (m^2).
    slots : ndarray of intp, shape (n, k)
        Rows of each measurement's candidates, padded with ``c`` (never nearest).
    allowed : ndarray of bool, shape (t, n)
        Pairs to gate; the others get index -1 and an infinite distance.

    Returns
    -------
    best : ndarray of int64, shape (t, n)
        Index (within the measurement's candidates) of the nearest candidate: the first
        smallest, or the first NaN, as :func:`numpy.argmin` picks.
    d2 : ndarray, shape (t, n)
        Its squared Mahalanobis distance.
    """
    n_tracks, n = allowed.shape
    width = slots.shape[1]
    c_total = z_xy.shape[0]
    best = np.full((n_tracks, n), -1, dtype=np.int64)
    d2 = np.full((n_tracks, n), np.inf)
    for i in range(n_tracks):
        mx, my = means_xy[i, 0], means_xy[i, 1]
        p00, p01, p10, p11 = covs_xy[i, 0, 0], covs_xy[i, 0, 1], covs_xy[i, 1, 0], covs_xy[i, 1, 1]
        for j in range(n):
            if not allowed[i, j]:
                continue
            bk = 0
            bv = np.inf
            for k in range(width):
                c = slots[j, k]
                if c >= c_total:
                    v = np.inf
                else:
                    a = p00 + cov[c, 0, 0]
                    b = p01 + cov[c, 0, 1]
                    cc = p10 + cov[c, 1, 0]
                    d = p11 + cov[c, 1, 1]
                    x = z_xy[c, 0] - mx
                    y = z_xy[c, 1] - my
                    v = (x * (d * x - b * y) + y * (a * y - cc * x)) / (a * d - b * cc)
                if math.isnan(v):
                    bk, bv = k, v
                    break
                if k == 0 or v < bv:
                    bk, bv = k, v
            best[i, j] = bk
            d2[i, j] = bv
    return best, d2
