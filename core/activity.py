"""Activity detectors on trajectories: loitering, rendezvous, convoys, zone crossings.

Collins et al. (1998) geolocate targets so that behaviour can be reasoned about in one
geospatial frame. These detectors read any trajectory with ``id``, ``cls``, ``t_s`` (n,)
and ``p_enu`` (n, 3) in the site frame (tracks from the tracker, or ground-truth paths)
and return :class:`ActivityEvent` values. Every threshold is a parameter with a physical
meaning; defaults suit people and cars on a site of a few hundred metres.

Definitions
-----------
Loitering
    A target stays inside a disc of radius ``radius_m`` for at least ``min_duration_s``
    (tested on the window's bounding box: half its diagonal at most ``radius_m``).
Rendezvous
    Two targets are within ``distance_m`` of each other while both are stopped (speed
    below ``stop_speed_mps``) for at least ``min_duration_s``.
Convoy
    A follower drives along the path its leader drove, within ``path_tolerance_m`` of it,
    a steady time lag behind (between ``min_lag_s`` and ``max_lag_s``, varying by at most
    ``lag_tolerance`` of its median), for at least ``min_distance_m``. Pairs that share a
    vehicle and overlap in time join into one convoy.
Zone crossing
    A target's position passes into (``zone-enter``) or out of (``zone-leave``) a polygon;
    the time is interpolated to the boundary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import shapely

__all__ = [
    "ActivityEvent",
    "ConvoyParams",
    "LoiterParams",
    "RendezvousParams",
    "Trajectory",
    "Zone",
    "detect_convoys",
    "detect_loitering",
    "detect_rendezvous",
    "detect_zone_crossings",
]


class Trajectory(Protocol):
    """What the detectors read: a :class:`~demtrack.core.tracking.types.Track` or truth."""

    @property
    def t_s(self) -> np.ndarray:
        """Times (n,), s, increasing."""
        ...

    @property
    def p_enu(self) -> np.ndarray:
        """Positions (n, 3), site frame (m)."""
        ...


@dataclass(frozen=True)
class ActivityEvent:
    """One detected activity.

    Attributes
    ----------
    kind : str
        ``loitering``, ``rendezvous``, ``convoy``, ``zone-enter`` or ``zone-leave``.
    t_start_s, t_end_s : float
        When it held (equal for zone crossings).
    track_ids : tuple of int
        The targets involved (a convoy lists the leader first).
    p_enu : ndarray, shape (3,)
        Where (mean position over the event), site frame (m).
    details : dict
        Kind-specific figures (radius, distance, lag, zone name, ...).
    """

    kind: str
    t_start_s: float
    t_end_s: float
    track_ids: tuple[int, ...]
    p_enu: np.ndarray
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "kind": self.kind,
            "t_start_s": self.t_start_s,
            "t_end_s": self.t_end_s,
            "track_ids": list(self.track_ids),
            "p_enu": [float(v) for v in self.p_enu],
            "details": dict(self.details),
        }


@dataclass(frozen=True)
class LoiterParams:
    """Loitering: inside a disc of ``radius_m`` for at least ``min_duration_s``."""

    radius_m: float = 10.0
    min_duration_s: float = 60.0


@dataclass(frozen=True)
class RendezvousParams:
    """Rendezvous: within ``distance_m``, both slower than ``stop_speed_mps``, for a while."""

    distance_m: float = 5.0
    stop_speed_mps: float = 0.5
    min_duration_s: float = 20.0
    dt_s: float = 1.0


@dataclass(frozen=True)
class ConvoyParams:
    """Convoy: follow the leader's path with a steady lag for ``min_distance_m``."""

    path_tolerance_m: float = 5.0
    min_lag_s: float = 0.5
    max_lag_s: float = 30.0
    lag_tolerance: float = 0.5
    min_distance_m: float = 100.0
    min_speed_mps: float = 1.0


@dataclass(frozen=True)
class Zone:
    """A named polygon in the site frame (m)."""

    name: str
    polygon: shapely.Polygon | shapely.MultiPolygon


def _ids(trajectories: Sequence[Any]) -> list[int]:
    return [int(getattr(t, "id", getattr(t, "target_id", k))) for k, t in enumerate(trajectories)]


def _runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[start, stop)`` where ``flag`` is True."""
    edges = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def detect_loitering(
    trajectories: Sequence[Trajectory], params: LoiterParams | None = None
) -> list[ActivityEvent]:
    """Episodes where a target stays within ``radius_m`` for ``min_duration_s`` or longer."""
    params = params or LoiterParams()
    out = []
    for tid, tr in zip(_ids(trajectories), trajectories, strict=True):
        t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
        n, j = len(t), 0
        best_end = np.full(n, -1)
        # Two pointers: the window [i, j] is "inside a disc" when half its bounding-box
        # diagonal is at most the radius; shrinking a window keeps that true.
        for i in range(n):
            j = max(j, i)
            while j + 1 < n:
                w = p[i : j + 2, :2]
                if np.hypot(*(w.max(axis=0) - w.min(axis=0))) / 2 > params.radius_m:
                    break
                j += 1
            best_end[i] = j
        qualifies = t[best_end] - t >= params.min_duration_s
        covered = np.zeros(n, bool)
        for i in np.flatnonzero(qualifies).tolist():
            covered[i : best_end[i] + 1] = True
        for a, b in _runs(covered):
            w = p[a:b]
            radius = float(np.hypot(*(w[:, :2].max(axis=0) - w[:, :2].min(axis=0))) / 2)
            out.append(
                ActivityEvent(
                    "loitering",
                    float(t[a]),
                    float(t[b - 1]),
                    (tid,),
                    w.mean(axis=0),
                    {"extent_radius_m": radius, "duration_s": float(t[b - 1] - t[a])},
                )
            )
    return out


def _resample(tr: Trajectory, grid: np.ndarray) -> np.ndarray:
    t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
    return np.column_stack([np.interp(grid, t, p[:, k]) for k in range(3)])


def _speed(p: np.ndarray, dt: float) -> np.ndarray:
    if len(p) < 2:
        return np.zeros(len(p))
    v = np.gradient(p[:, :2], dt, axis=0)
    return np.hypot(v[:, 0], v[:, 1])


def detect_rendezvous(
    trajectories: Sequence[Trajectory], params: RendezvousParams | None = None
) -> list[ActivityEvent]:
    """Pairs of targets stopped together for at least ``min_duration_s``."""
    params = params or RendezvousParams()
    ids = _ids(trajectories)
    out = []
    for a in range(len(trajectories)):
        for b in range(a + 1, len(trajectories)):
            ta, tb = trajectories[a].t_s, trajectories[b].t_s
            if len(ta) < 2 or len(tb) < 2:
                continue
            lo, hi = max(ta[0], tb[0]), min(ta[-1], tb[-1])
            if hi - lo < params.min_duration_s:
                continue
            grid = np.arange(lo, hi + 1e-9, params.dt_s)
            pa, pb = _resample(trajectories[a], grid), _resample(trajectories[b], grid)
            close = np.hypot(*(pa[:, :2] - pb[:, :2]).T) <= params.distance_m
            still = (_speed(pa, params.dt_s) < params.stop_speed_mps) & (
                _speed(pb, params.dt_s) < params.stop_speed_mps
            )
            for s, e in _runs(close & still):
                if grid[e - 1] - grid[s] >= params.min_duration_s:
                    mid = (pa[s:e] + pb[s:e]).mean(axis=0) / 2
                    gap = float(np.hypot(*(pa[s:e, :2] - pb[s:e, :2]).T).mean())
                    out.append(
                        ActivityEvent(
                            "rendezvous",
                            float(grid[s]),
                            float(grid[e - 1]),
                            (ids[a], ids[b]),
                            mid,
                            {"mean_distance_m": gap, "duration_s": float(grid[e - 1] - grid[s])},
                        )
                    )
    return out


def _follow_stretches(
    leader: Trajectory, follower: Trajectory, params: ConvoyParams
) -> list[tuple[float, float, float, float]]:
    """Stretches where ``follower`` drives the leader's path a steady lag behind.

    Returns ``(t_start, t_end, median_lag_s, distance_m)`` per stretch.
    """
    tl, pl = np.asarray(leader.t_s, float), np.asarray(leader.p_enu, float)
    tf, pf = np.asarray(follower.t_s, float), np.asarray(follower.p_enu, float)
    if len(tl) < 2 or len(tf) < 2:
        return []
    path = shapely.LineString(pl[:, :2])
    seg = np.hypot(*np.diff(pl[:, :2], axis=0).T)
    s_leader = np.concatenate([[0.0], np.cumsum(seg)])
    pts = shapely.points(pf[:, 0], pf[:, 1])
    off_path = shapely.distance(pts, path)
    s_on = shapely.line_locate_point(path, pts)
    t_there = np.interp(s_on, s_leader, tl)  # when the leader was where the follower is
    lag = tf - t_there
    moving = _speed(pf, float(np.median(np.diff(tf))) if len(tf) > 1 else 1.0)
    ok = (
        (off_path <= params.path_tolerance_m)
        & (lag >= params.min_lag_s)
        & (lag <= params.max_lag_s)
        & (moving >= params.min_speed_mps)
    )
    out = []
    for a, b in _runs(ok):
        lags = lag[a:b]
        med = float(np.median(lags))
        if np.max(np.abs(lags - med)) > params.lag_tolerance * med + 1.0:
            continue
        dist = float(np.sum(np.hypot(*np.diff(pf[a:b, :2], axis=0).T)))
        if dist >= params.min_distance_m:
            out.append((float(tf[a]), float(tf[b - 1]), med, dist))
    return out


def detect_convoys(
    trajectories: Sequence[Trajectory], params: ConvoyParams | None = None
) -> list[ActivityEvent]:
    """Groups of two or more targets driving the same path in order, steadily spaced."""
    params = params or ConvoyParams()
    ids = _ids(trajectories)
    pairs = []
    for a, lead in enumerate(trajectories):
        for b, follow in enumerate(trajectories):
            if a != b:
                for t0, t1, lag, dist in _follow_stretches(lead, follow, params):
                    pairs.append((a, b, t0, t1, lag, dist))
    # Join pairs that share a vehicle and overlap in time (a leader-follower chain).
    groups: list[dict[str, Any]] = []
    for a, b, t0, t1, lag, dist in sorted(pairs, key=lambda q: q[2]):
        for g in groups:
            if ({a, b} & g["members"]) and t0 <= g["t1"] and t1 >= g["t0"]:
                g["members"] |= {a, b}
                g["t0"], g["t1"] = min(g["t0"], t0), max(g["t1"], t1)
                g["lags"].append(lag)
                g["dist"] = max(g["dist"], dist)
                g["order"].append((a, b))
                break
        else:
            groups.append(
                {
                    "members": {a, b},
                    "t0": t0,
                    "t1": t1,
                    "lags": [lag],
                    "dist": dist,
                    "order": [(a, b)],
                }
            )
    out = []
    for g in groups:
        followers = {b for _, b in g["order"]}
        order = sorted(g["members"], key=lambda k: (k in followers, k))
        mid_t = (g["t0"] + g["t1"]) / 2
        centre = np.mean([_resample(trajectories[k], np.array([mid_t]))[0] for k in order], axis=0)
        out.append(
            ActivityEvent(
                "convoy",
                g["t0"],
                g["t1"],
                tuple(ids[k] for k in order),
                centre,
                {"lags_s": [float(x) for x in g["lags"]], "distance_m": g["dist"]},
            )
        )
    return out


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
