"""Compiled kernels of the two-ray fusion (:mod:`demtrack.core.tracking.fusion`).

The fusion screens every (a, b) pair of two sensors' fixes of one step and triangulates
the pairs it matches. With a handful of fixes per sensor, the numpy forms of these steps
spent their time in the overhead of some fifty small array operations per call; these
kernels do the same arithmetic in one pass. Plain-numpy twins:
:func:`demtrack.core.tracking.reference.screen_pairs_reference` and
:func:`~demtrack.core.tracking.reference.triangulation_cov_reference` (the tests
compare them on random pairs).

Arrays only; the checks and the scalar fall-back for pairs at a threshold's round-off stay
in :mod:`~demtrack.core.tracking.fusion`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["screen_pairs_kernel", "triangulation_cov_kernel"]


@njit(cache=True, error_model="numpy")
def screen_pairs_kernel(  # pragma: no cover - numba
    oa, da, ta, ca, hxa, sga, cva, ob, db, tb, cb, hxb, sgb, cvb, window_s, min_sin, max_miss, gate
):
    """Closest approach, check slacks and pair cost of every (a, b) pair.

    Parameters
    ----------
    oa, da : ndarray, float64, shape (na, 3)
        Origins (m) and unit directions of side a's rays; ``ob``, ``db`` side b's.
    ta, ca : ndarray, shape (na,)
        Times (s) and class codes (int64); ``tb``, ``cb`` side b's.
    hxa, sga, cva : ndarray, shape (na, k, 2), (na, k), (na, k, 2, 2)
        Hits' horizontal positions, sigmas and covariances, NaN-padded; ``hxb`` ... b's.
    window_s, min_sin, max_miss, gate : float
        Step window (s), sine of the least ray angle, longest common perpendicular (m),
        hit gate (sigmas).

    Returns
    -------
    same : ndarray, bool, (na, nb)
        Same class and within the step window.
    worst : ndarray, (na, nb)
        Smallest slack of the checks (> 0: all pass; NaN slacks count as -inf).
    d2 : ndarray, (na, nb)
        Pair cost: each side's smallest squared Mahalanobis distance to a hit, summed.
    p, miss, s, t, sin_angle : ndarray, (na, nb, 3), (na, nb) x 4
        Midpoint of the common perpendicular, its length, ranges along a and b, sine of
        the angle between the rays.
    """
    na, nb = oa.shape[0], ob.shape[0]
    same = np.empty((na, nb), np.bool_)
    worst = np.empty((na, nb))
    d2 = np.empty((na, nb))
    p = np.empty((na, nb, 3))
    miss = np.empty((na, nb))
    s_out = np.empty((na, nb))
    t_out = np.empty((na, nb))
    sin_out = np.empty((na, nb))
    pa = np.empty(3)
    pb = np.empty(3)
    for i in range(na):
        for j in range(nb):
            same[i, j] = ca[i] == cb[j] and abs(ta[i] - tb[j]) <= window_s
            b = da[i, 0] * db[j, 0] + da[i, 1] * db[j, 1] + da[i, 2] * db[j, 2]
            denom = 1.0 - b * b
            d = 0.0
            e = 0.0
            for k in range(3):
                w0 = oa[i, k] - ob[j, k]
                d += da[i, k] * w0
                e += db[j, k] * w0
            s = (b * e - d) / denom
            t = (e - b * d) / denom
            m2 = 0.0
            for k in range(3):
                pa[k] = oa[i, k] + s * da[i, k]
                pb[k] = ob[j, k] + t * db[j, k]
                p[i, j, k] = 0.5 * (pa[k] + pb[k])
                m2 += (pa[k] - pb[k]) ** 2
            mi = math.sqrt(m2)
            sin_angle = math.sin(math.acos(min(1.0, max(-1.0, b))))
            near_a = _near(hxa[i], sga[i], p[i, j, 0], p[i, j, 1], gate)
            near_b = _near(hxb[j], sgb[j], p[i, j, 0], p[i, j, 1], gate)
            w = math.inf
            for v in (denom - 1e-12, sin_angle - min_sin, max_miss - mi, s, t, near_a, near_b):
                w = min(w, -math.inf if math.isnan(v) else v)
            worst[i, j] = w
            d2[i, j] = _min_d2(hxa[i], cva[i], p[i, j, 0], p[i, j, 1]) + _min_d2(
                hxb[j], cvb[j], p[i, j, 0], p[i, j, 1]
            )
            miss[i, j] = mi
            s_out[i, j] = s
            t_out[i, j] = t
            sin_out[i, j] = sin_angle
    return same, worst, d2, p, miss, s_out, t_out, sin_out


@njit(cache=True, inline="always", error_model="numpy")
def _near(hx, sg, x, y, gate):  # pragma: no cover - numba
    """Largest ``gate * sigma + 1 - distance`` over a fix's hits (-inf without hits)."""
    best = -math.inf
    for k in range(hx.shape[0]):
        v = gate * sg[k] + 1.0 - math.hypot(hx[k, 0] - x, hx[k, 1] - y)
        if not math.isnan(v) and v > best:
            best = v
    return best


@njit(cache=True, inline="always", error_model="numpy")
def _min_d2(hx, cv, x, y):  # pragma: no cover - numba
    """Smallest squared Mahalanobis distance of (x, y) to a fix's hits (inf without hits)."""
    best = math.inf
    for k in range(hx.shape[0]):
        dx = hx[k, 0] - x
        dy = hx[k, 1] - y
        a, b, c = cv[k, 0, 0], cv[k, 0, 1], cv[k, 1, 1]
        v = (c * dx * dx - 2 * b * dx * dy + a * dy * dy) / (a * c - b * b)
        if not math.isnan(v) and v < best:
            best = v
    return best


@njit(cache=True, error_model="numpy")
def triangulation_cov_kernel(  # pragma: no cover - numba
    p, miss, sin_angle, range_a, range_b, ga, gb, hxa, cva, hxb, cvb, ray_sigma
):
    """Covariance (m, 2, 2) and worst-direction sigma (m,) of matched triangulations.

    Parameters
    ----------
    p : ndarray, (m, 3)
        Triangulated points (m).
    miss, sin_angle, range_a, range_b : ndarray, (m,)
        Common perpendicular (m), sine of the ray angle, ranges along each ray (m).
    ga, gb : ndarray, (m, 2)
        Horizontal parts of each side's ray direction.
    hxa, cva, hxb, cvb : ndarray, (m, k, 2), (m, k, 2, 2)
        Each side's NaN-padded hits and their covariances.
    ray_sigma : float
        Angular sigma of a ray (rad).
    """
    m = p.shape[0]
    cov = np.empty((m, 2, 2))
    sigma = np.empty(m)
    for r in range(m):
        sa = ray_sigma * range_a[r]
        sb = ray_sigma * range_b[r]
        worst = math.sqrt(0.5 * (sa * sa + sb * sb)) / sin_angle[r]
        i00 = 1.0 / (worst * worst)
        i01 = 0.0
        i11 = i00
        for side in range(2):
            if side == 0:
                g0, g1, s, hx, cv = ga[r, 0], ga[r, 1], sa, hxa[r], cva[r]
            else:
                g0, g1, s, hx, cv = gb[r, 0], gb[r, 1], sb, hxb[r], cvb[r]
            norm = math.hypot(g0, g1)
            vertical = norm < 1e-9
            n0, n1 = (1.0, 0.0) if vertical else (-g1 / norm, g0 / norm)
            near, best = 0, math.inf
            for k in range(hx.shape[0]):
                dd = (hx[k, 0] - p[r, 0]) ** 2 + (hx[k, 1] - p[r, 1]) ** 2
                if not math.isnan(dd) and dd < best:
                    near, best = k, dd
            var = n0 * (cv[near, 0, 0] * n0 + cv[near, 0, 1] * n1) + n1 * (
                cv[near, 1, 0] * n0 + cv[near, 1, 1] * n1
            )
            s = max(s, math.sqrt(var))
            w = 1.0 / (s * s)
            if vertical:
                i00 += w
                i11 += w
            else:
                i00 += n0 * n0 * w
                i01 += n0 * n1 * w
                i11 += n1 * n1 * w
        det = i00 * i11 - i01 * i01
        extra = max(0.5 * miss[r], 0.05) ** 2
        c00 = i11 / det + extra
        c11 = i00 / det + extra
        c01 = -i01 / det
        cov[r, 0, 0] = c00
        cov[r, 0, 1] = c01
        cov[r, 1, 0] = c01
        cov[r, 1, 1] = c11
        half_tr = 0.5 * (c00 + c11)
        half_diff = 0.5 * (c00 - c11)
        sigma[r] = math.sqrt(half_tr + math.hypot(half_diff, c01))
    return cov, sigma
