"""Road-following extrapolation: where a vehicle seen at ``p`` moving at ``v`` will be.

A vehicle on a road follows it: predicted in a straight line over a long absence it ends
up in the fields beside a bend. :func:`follow_road` carries the position along the
nearest road centreline at the current speed, in the direction of travel, keeping the
lateral (lane) offset; past either end of the line it continues straight. Shared by
hand-off prediction (:mod:`demtrack.core.visibility.handoff`) and track re-acquisition
(:mod:`.reacquire`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from shapely import LineString

__all__ = ["follow_road"]


def follow_road(
    lines: Sequence[LineString],
    p_xy: np.ndarray,
    v_xy: np.ndarray,
    times_s: np.ndarray,
    snap_m: float = 5.0,
) -> np.ndarray | None:
    """Future horizontal positions following the nearest road.

    Parameters
    ----------
    lines : sequence of shapely.LineString
        Road centrelines, local frame (m).
    p_xy : array_like, shape (>= 2,)
        Current position (m); only x, y are used.
    v_xy : array_like, shape (>= 2,)
        Current velocity (m/s); only x, y are used.
    times_s : ndarray, shape (n,)
        Times ahead (s, >= 0).
    snap_m : float
        A position farther than this from every road is off the roads.

    Returns
    -------
    ndarray, shape (n, 2), or None
        Positions (m); None when off the roads, without roads, or nearly at rest
        (speed below 0.1 m/s).
    """
    if not len(lines):
        return None
    p = np.asarray(p_xy, dtype=np.float64)
    v = np.asarray(v_xy, dtype=np.float64)
    times = np.asarray(times_s, dtype=np.float64)
    speed = float(np.hypot(v[0], v[1]))
    here = shapely.Point(p[0], p[1])
    k = int(np.argmin([line.distance(here) for line in lines]))
    line = lines[k]
    if speed < 0.1 or line.distance(here) > snap_m:
        return None
    s0 = line.project(here)
    ahead = line.interpolate(min(s0 + 1.0, line.length))
    behind = line.interpolate(max(s0 - 1.0, 0.0))
    tangent = np.array([ahead.x - behind.x, ahead.y - behind.y])
    sign = 1.0 if tangent @ v[:2] >= 0 else -1.0
    on = line.interpolate(s0)
    offset = np.array([p[0] - on.x, p[1] - on.y])  # keep the lane offset
    s = s0 + sign * speed * times
    if line.is_closed:
        s = np.mod(s, line.length)
    pts = shapely.get_coordinates(shapely.line_interpolate_point(line, np.clip(s, 0, line.length)))
    # Past either end of the line, carry on in a straight line.
    over = np.maximum(np.where(s > line.length, s - line.length, 0), np.where(s < 0, -s, 0))
    step = sign * tangent / max(float(np.linalg.norm(tangent)), 1e-9)
    pts = pts + offset + over[:, None] * step
    return pts
