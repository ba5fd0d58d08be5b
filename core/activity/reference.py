"""Straightforward reference twins of the activity detectors (for tests).

:func:`detect_rendezvous_reference` and :func:`detect_convoys_reference` are the
all-pairs versions :mod:`demtrack.core.activity.detectors` started from: every pair of
trajectories goes through the full test, nothing is pruned.
:func:`detect_loitering_reference` grows each window point by point. The optimised
detectors must return exactly the same events (``tests/core/activity/test_activity_reference.py``),
as the numba kernels are checked against their plain-numpy twins.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

from .convoy import ConvoyParams, _step_s, convoys_of_pairs
from .detectors import ActivityEvent, Trajectory, _ids, _resample, _runs, _speed
from .loitering import LoiterParams
from .rendezvous import RendezvousParams

__all__ = [
    "detect_convoys_reference",
    "detect_loitering_reference",
    "detect_rendezvous_reference",
]


def detect_loitering_reference(
    trajectories: Sequence[Trajectory], params: LoiterParams | None = None
) -> list[ActivityEvent]:
    """Two-pointer ``detect_loitering`` of :mod:`..detectors` (a numpy call per step)."""
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


def detect_rendezvous_reference(
    trajectories: Sequence[Trajectory], params: RendezvousParams | None = None
) -> list[ActivityEvent]:
    """All-pairs :func:`~demtrack.core.activity.detectors.detect_rendezvous`."""
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
            grid = lo + np.arange(0.0, hi - lo + 1e-9, params.dt_s)  # relative: UNIX times
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


def _follow_stretches_reference(
    leader: Trajectory, follower: Trajectory, params: ConvoyParams
) -> list[tuple[float, float, float, float]]:
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
    t_there = np.interp(s_on, s_leader, tl)
    lag = tf - t_there
    moving = _speed(pf, _step_s(tf))
    ok = (
        (off_path <= params.path_tolerance_m)
        & (lag >= params.min_lag_s)
        & (lag <= params.max_lag_s)
        & (moving >= params.min_speed_mps)
    )
    out = []
    for a, b in _runs(ok):
        lags, tr = lag[a:b], tf[a:b]
        med = float(np.median(lags))
        # running median, one window at a time
        w = params.lag_window_s
        local = [np.median(lags[(tr >= ti - w) & (tr <= ti + w)]) for ti in tr]
        if np.max(np.abs(np.asarray(local) - med)) > params.lag_tolerance * med + 1.0:
            continue
        dist = float(np.sum(np.hypot(*np.diff(pf[a:b, :2], axis=0).T)))
        if dist >= params.min_distance_m:
            out.append((float(tf[a]), float(tf[b - 1]), med, dist))
    return out


def detect_convoys_reference(
    trajectories: Sequence[Trajectory], params: ConvoyParams | None = None
) -> list[ActivityEvent]:
    """All-pairs :func:`~demtrack.core.activity.detectors.detect_convoys`."""
    params = params or ConvoyParams()
    pairs = []
    for a, lead in enumerate(trajectories):
        for b, follow in enumerate(trajectories):
            if a != b:
                for t0, t1, lag, dist in _follow_stretches_reference(lead, follow, params):
                    pairs.append((a, b, t0, t1, lag, dist))
    return convoys_of_pairs(trajectories, pairs)
