"""OSPA and GOSPA distances between finite sets of points.

OSPA (Schuhmacher, Vo & Vo 2008, "A consistent metric for performance evaluation of
multi-object filters"), for ``X`` of size ``m`` and ``Y`` of size ``n``, ``m <= n``
(else swap), cut-off ``c`` and order ``p``::

    d(X, Y) = ( (1/n) ( min_pi sum_i min(c, |x_i - y_pi(i)|)^p + c^p (n - m) ) )^(1/p)

with ``d = 0`` when both are empty and ``c`` when exactly one is.

GOSPA (Rahmathullah, Garcia-Fernandez & Svensson 2017, "Generalized optimal
sub-pattern assignment metric") with ``alpha = 2``::

    d(X, Y) = ( min_gamma sum_(i,j) in gamma |x_i - y_j|^p + (c^p / 2) (m + n - 2 |gamma|) )^(1/p)

over partial assignments ``gamma`` of pairs closer than ``c``; it splits into a
localisation part and missed / false target parts. Both optimal assignments are solved
exactly with :func:`scipy.optimize.linear_sum_assignment`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import TrackingError

__all__ = ["GospaResult", "gospa", "ospa"]


def _check(c: float, p: float) -> None:
    if not (math.isfinite(c) and c > 0):
        raise TrackingError(f"cut-off c must be positive, got {c}")
    if not (math.isfinite(p) and p >= 1):
        raise TrackingError(f"order p must be >= 1, got {p}")


def _points(a: np.ndarray) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, arr.shape[-1] if arr.ndim == 2 else 2)
    if arr.ndim != 2:
        raise TrackingError(f"point sets must have shape (k, d), got {arr.shape}")
    return arr


def _distances(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    if x.shape[1] != y.shape[1]:
        raise TrackingError(f"point dimensions differ: {x.shape[1]} vs {y.shape[1]}")
    return np.linalg.norm(x[:, None, :] - y[None, :, :], axis=2)


def ospa(x: np.ndarray, y: np.ndarray, c: float = 10.0, p: float = 2.0) -> float:
    """OSPA distance between point sets ``x`` (m, d) and ``y`` (n, d) (m).

    Parameters
    ----------
    x, y : ndarray, shape (m, d) and (n, d)
        Points (e.g. true and estimated positions at one time).
    c : float
        Cut-off (m): the penalty of a missing or extra point.
    p : float
        Order (>= 1).
    """
    _check(c, p)
    x, y = _points(x), _points(y)
    m, n = x.shape[0], y.shape[0]
    if m == 0 and n == 0:
        return 0.0
    if m == 0 or n == 0:
        return float(c)
    if m > n:
        x, y, m, n = y, x, n, m
    cost = np.minimum(_distances(x, y), c) ** p
    rows, cols = linear_sum_assignment(cost)
    total = float(cost[rows, cols].sum()) + c**p * (n - m)
    return float((total / n) ** (1.0 / p))


@dataclass(frozen=True)
class GospaResult:
    """GOSPA distance and its parts (alpha = 2).

    Parameters
    ----------
    distance : float
        GOSPA distance (m).
    localisation : float
        Sum of ``d^p`` over assigned pairs (m^p).
    missed : int
        Points of ``x`` (truth) left unassigned.
    false : int
        Points of ``y`` (estimates) left unassigned.
    """

    distance: float
    localisation: float
    missed: int
    false: int


def gospa(x: np.ndarray, y: np.ndarray, c: float = 10.0, p: float = 2.0) -> GospaResult:
    """GOSPA distance (alpha = 2) between truth ``x`` (m, d) and estimates ``y`` (n, d).

    Parameters
    ----------
    x, y : ndarray, shape (m, d) and (n, d)
        True and estimated points.
    c : float
        Cut-off (m); leaving a point unassigned costs ``c^p / 2``.
    p : float
        Order (>= 1).
    """
    _check(c, p)
    x, y = _points(x), _points(y)
    m, n = x.shape[0], y.shape[0]
    if m == 0 or n == 0:
        total = c**p / 2.0 * (m + n)
        return GospaResult(float(total ** (1.0 / p)), 0.0, m, n)
    d = _distances(x, y)
    # Assigning a pair at distance >= c costs at least c^p = two unassigned points, so
    # the min over partial assignments is the full assignment of min(d, c)^p, plus
    # c^p/2 per point left over; pairs at the cut-off count as missed + false.
    cost = np.minimum(d, c) ** p
    rows, cols = linear_sum_assignment(cost)
    real = d[rows, cols] < c
    loc = float(np.sum(d[rows, cols][real] ** p))
    n_pairs = int(real.sum())
    missed, false = m - n_pairs, n - n_pairs
    total = loc + c**p / 2.0 * (missed + false)
    return GospaResult(float(total ** (1.0 / p)), loc, missed, false)
