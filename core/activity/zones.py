"""Zone crossings: a target passes into (``zone-enter``) or out of (``zone-leave``) a polygon.

The time of a crossing is interpolated to the boundary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from .detectors import ActivityEvent, Trajectory, _ids

__all__ = [
    "Zone",
    "detect_zone_crossings",
]


@dataclass(frozen=True)
class Zone:
    """A named polygon in the site frame (m)."""

    name: str
    polygon: shapely.Polygon | shapely.MultiPolygon


def detect_zone_crossings(
    trajectories: Sequence[Trajectory], zones: Sequence[Zone]
) -> list[ActivityEvent]:
    """Entries into and exits from each zone, time-interpolated to the boundary."""
    out = []
    for tid, tr in zip(_ids(trajectories), trajectories, strict=True):
        t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
        if len(t) < 2:
            continue
        for zone in zones:
            inside = shapely.contains_xy(zone.polygon, p[:, 0], p[:, 1])
            for k in np.flatnonzero(inside[1:] != inside[:-1]):
                seg = shapely.LineString(p[k : k + 2, :2])
                cross = shapely.intersection(seg, zone.polygon.boundary)
                xy = shapely.get_coordinates(cross)
                frac = (
                    float(np.hypot(*(xy[0] - p[k, :2])) / max(seg.length, 1e-12))
                    if len(xy)
                    else 0.5
                )
                tc = float(t[k] + frac * (t[k + 1] - t[k]))
                where = p[k] + frac * (p[k + 1] - p[k])
                kind = "zone-enter" if inside[k + 1] else "zone-leave"
                out.append(ActivityEvent(kind, tc, tc, (tid,), where, {"zone": zone.name}))
    return sorted(out, key=lambda e: e.t_start_s)
