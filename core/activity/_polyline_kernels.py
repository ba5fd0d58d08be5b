"""numba kernel: points projected onto a polyline (distance to it, length along it).

The convoy test (:mod:`demtrack.core.activity.detectors`) asks, for each of a follower's points,
how far it is from the leader's path and where along that path (m from its start) the
nearest point lies: what ``shapely.distance(points, line)`` and
``shapely.line_locate_point(line, points)`` answer. This kernel answers both in one pass
over the segments, with GEOS's arithmetic in GEOS's order, so it gives the same bits:

* distance to a segment ``A B`` (GEOS ``Distance::pointToSegment``): ``|P A|`` when
  ``A == B`` or the projection factor ``r <= 0``, ``|P B|`` when ``r >= 1``, else
  ``|s| * sqrt(len2)`` with ``s`` the signed perpendicular factor; each length
  ``sqrt(dx * dx + dy * dy)``;
* the distance to the line is the least segment distance; the located length is that of
  the first segment (along the line) holding it (GEOS ``LengthIndexOfPoint``: a later
  segment must be strictly nearer), ``start + f * |A B|`` with ``f`` the projection
  factor clamped to ``[0, 1]`` (0 when ``P == A``, 1 when ``P == B``), ``start`` the sum
  of the segment lengths before it, added in order.

:func:`project_points_reference` is the plain-numpy twin (tests compare the two).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["project_points_kernel", "project_points_reference"]


@njit(cache=True, error_model="numpy")
def project_points_kernel(lx, ly, px, py, dist, along):  # pragma: no cover - numba
    """Distance from each point to the polyline, and the length along it of the nearest.

    Parameters
    ----------
    lx, ly : float64 (n,), n >= 2
        The polyline's vertices (m).
    px, py : float64 (m,)
        The points (m).
    dist, along : float64 (m,) out
        Distance to the polyline and located length along it (m), as GEOS gives them.
    """
    n = lx.shape[0]
    for i in range(px.shape[0]):
        x = px[i]
        y = py[i]
        best = math.inf
        where = -1.0
        start = 0.0
        for k in range(n - 1):
            ax = lx[k]
            ay = ly[k]
            bx = lx[k + 1]
            by = ly[k + 1]
            dx = bx - ax
            dy = by - ay
            len2 = dx * dx + dy * dy
            seg = math.sqrt((ax - bx) * (ax - bx) + (ay - by) * (ay - by))
            if ax == bx and ay == by:
                d = math.sqrt((x - ax) * (x - ax) + (y - ay) * (y - ay))
                r = math.nan
            else:
                r = ((x - ax) * dx + (y - ay) * dy) / len2
                if r <= 0.0:
                    d = math.sqrt((x - ax) * (x - ax) + (y - ay) * (y - ay))
                elif r >= 1.0:
                    d = math.sqrt((x - bx) * (x - bx) + (y - by) * (y - by))
                else:
                    s = ((ay - y) * dx - (ax - x) * dy) / len2
                    d = abs(s) * math.sqrt(len2)
            if d < best:
                best = d
                if x == ax and y == ay:
                    f = 0.0
                elif x == bx and y == by:
                    f = 1.0
                else:
                    f = r  # NaN (a zero-length segment) falls to the last case below
                if f <= 0.0:
                    where = start
                elif f <= 1.0:
                    where = start + f * seg
                else:
                    where = start + seg
            start += seg
        dist[i] = best
        along[i] = where


def project_points_reference(line_xy: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy twin of :func:`project_points_kernel`.

    Parameters
    ----------
    line_xy : ndarray, shape (n, 2), n >= 2
        The polyline's vertices (m).
    xy : ndarray, shape (m, 2)
        The points (m).

    Returns
    -------
    dist, along : ndarray, shape (m,)
        Distance to the polyline, and located length along it (m).
    """
    lx, ly = line_xy[:, 0], line_xy[:, 1]
    ax, ay, bx, by = lx[None, :-1], ly[None, :-1], lx[None, 1:], ly[None, 1:]
    x, y = xy[:, 0:1], xy[:, 1:2]
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    seg = np.sqrt((ax - bx) * (ax - bx) + (ay - by) * (ay - by))
    point = (ax == bx) & (ay == by)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(point, np.nan, ((x - ax) * dx + (y - ay) * dy) / len2)
        s = ((ay - y) * dx - (ax - x) * dy) / len2
    d_a = np.sqrt((x - ax) * (x - ax) + (y - ay) * (y - ay))
    d_b = np.sqrt((x - bx) * (x - bx) + (y - by) * (y - by))
    d = np.where(point | (r <= 0.0), d_a, np.where(r >= 1.0, d_b, np.abs(s) * np.sqrt(len2)))
    k = np.argmin(d, axis=1)  # the first of equal least values
    rows = np.arange(len(xy))
    starts = np.concatenate([[0.0], np.cumsum(seg[0])])[:-1]  # cumsum adds in order
    at_a = (x[:, 0] == ax[0, k]) & (y[:, 0] == ay[0, k])
    at_b = (x[:, 0] == bx[0, k]) & (y[:, 0] == by[0, k])
    f = np.where(at_a, 0.0, np.where(at_b, 1.0, r[rows, k]))
    sk = seg[0, k]
    with np.errstate(invalid="ignore"):
        along = np.where(
            f <= 0.0, starts[k], np.where(f <= 1.0, starts[k] + f * sk, starts[k] + sk)
        )
    return d[rows, k], along
