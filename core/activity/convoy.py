"""Convoys: a follower drives along its leader's path, a steady time lag behind.

A follower drives along the path its leader drove, within ``path_tolerance_m`` of it, a
steady time lag behind (between ``min_lag_s`` and ``max_lag_s``; its running median over
``lag_window_s`` either side varies by at most ``lag_tolerance`` of the median lag + 1 s),
for at least ``min_distance_m``. Pairs that share a vehicle and overlap in time join into
one convoy. Points are projected onto the leader's path by the numba polyline kernel
(``core.activity._polyline_kernels``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._polyline_kernels import project_points_kernel
from .detectors import (
    _EPS,
    ActivityEvent,
    Trajectory,
    _box_gaps,
    _extents,
    _ids,
    _range_box,
    _range_tables,
    _resample,
    _speed,
)

__all__ = [
    "ConvoyParams",
    "convoys_of_pairs",
    "detect_convoys",
]


@dataclass(frozen=True)
class ConvoyParams:
    """Convoy: follow the leader's path with a steady lag for ``min_distance_m``.

    The steadiness test reads the lag's running median over ``lag_window_s`` either side
    of each point (s), not the pointwise lag: where the leader's path crosses itself (a
    turn at a junction), the nearest point of the path to a follower's fix near the
    crossing can lie on the other pass, and that fix's lag is off by the time between
    the passes. The follower is near the crossing for a moment (a fraction of a second at
    driving speed), while a real change of lag builds up over seconds.
    """

    path_tolerance_m: float = 5.0
    min_lag_s: float = 0.5
    max_lag_s: float = 30.0
    lag_tolerance: float = 0.5
    min_distance_m: float = 100.0
    min_speed_mps: float = 1.0
    lag_window_s: float = 1.0


def _step_s(t: np.ndarray) -> float:
    """Typical time step of ``t`` (n,) (s), never 0.

    The median step, or when that is 0 the median of the positive steps (1 s when there
    is none). A fused track holds one point per camera's fix, so several points can share a time;
    when most do, the median step is 0 and speeds over it would be 0/0.
    """
    steps = np.diff(t)
    med = float(np.median(steps)) if len(steps) else 0.0
    if med > 0:
        return med
    steps = steps[steps > 0]
    return float(np.median(steps)) if len(steps) else 1.0


def _running_median(t: np.ndarray, x: np.ndarray, half_s: float) -> np.ndarray:
    """Median of ``x`` over the points within ``half_s`` of each point's time, shape (n,).

    ``t`` (n,) non-decreasing (s); the window of point ``i`` holds every ``j`` with
    ``t[i] - half_s <= t[j] <= t[i] + half_s`` (``i`` included, cut at the ends).
    """
    if not len(t):
        return np.zeros(0)
    lo = np.searchsorted(t, t - half_s, side="left")
    hi = np.searchsorted(t, t + half_s, side="right")
    idx = lo[:, None] + np.arange(int(np.max(hi - lo)))
    # windows padded with +inf, sorted: each row's first hi - lo values are its window
    rows = np.sort(np.where(idx < hi[:, None], x[np.minimum(idx, len(t) - 1)], np.inf), axis=1)
    count, k = hi - lo, np.arange(len(t))
    return (rows[k, (count - 1) // 2] + rows[k, count // 2]) / 2


@dataclass(eq=False)
class _Drive:
    """One trajectory's figures for the convoy test, computed once per call.

    ``s_m`` (n,) is the cumulative horizontal path length (m); ``moving`` (n,) the speed
    (m/s), ``path`` (the horizontal vertices as two contiguous arrays, for
    :func:`~demtrack.core.activity._polyline_kernels.project_points_kernel`) and ``tables``
    (:func:`_range_tables` of the positions) are made when first needed.
    """

    t: np.ndarray
    p: np.ndarray
    s_m: np.ndarray
    _moving: np.ndarray | None = None
    _path: tuple[np.ndarray, np.ndarray] | None = None
    _tables: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def of(cls, tr: Trajectory) -> _Drive:
        t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
        seg = np.hypot(*np.diff(p[:, :2], axis=0).T)
        return cls(t, p, np.concatenate([[0.0], np.cumsum(seg)]))

    @property
    def moving(self) -> np.ndarray:
        # only a possible follower's speed is read: most leaders never need it
        if self._moving is None:
            self._moving = _speed(self.p, _step_s(self.t))
        return self._moving

    @property
    def path(self) -> tuple[np.ndarray, np.ndarray]:
        if self._path is None:
            self._path = (np.ascontiguousarray(self.p[:, 0]), np.ascontiguousarray(self.p[:, 1]))
        return self._path

    @property
    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        if self._tables is None:
            self._tables = _range_tables(self.p[:, :2])
        return self._tables


def _project(leader: _Drive, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each point ``xy`` (m, 2) to the leader's path, and the length along it.

    The same bits as ``shapely.distance(points, line)`` and
    ``shapely.line_locate_point(line, points)`` of the path's ``LineString`` (see
    :mod:`~demtrack.core.activity._polyline_kernels`), both in one pass, without making shapely
    points.
    """
    dist, along = np.empty(len(xy)), np.empty(len(xy))
    if len(xy):
        lx, ly = leader.path
        px, py = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
        project_points_kernel(lx, ly, px, py, dist, along)
    return dist, along


def _follow_stretches(
    leader: _Drive, fleet: _Fleet, params: ConvoyParams, cand: np.ndarray
) -> list[tuple[int, float, float, float, float]]:
    """Stretches where a fleet trajectory drives the leader's path a steady lag behind.

    Returns ``(follower, t_start, t_end, median_lag_s, distance_m)`` per stretch, in fleet
    order (follower by follower, in time). ``cand`` (N,) marks the fleet points that pass
    the cheap necessary conditions (:func:`_candidates`) of followers worth testing; the
    exact test (distance to the leader's path, lag) runs on those only, for all followers
    at once (each point's answer is its own), and every other point fails it. A run of
    passing points of one follower is steady when the running median of its lags
    (:func:`_running_median`, ``lag_window_s``) stays within ``lag_tolerance`` of the
    run's median lag + 1 s.
    """
    tl, tf, xy = leader.t, fleet.t, fleet.xy
    idx = np.flatnonzero(cand)
    off_path, s_on = _project(leader, xy[idx])
    t_there = np.interp(s_on, leader.s_m, tl)  # when the leader was where the follower is
    lag = np.zeros(len(tf))
    lag[idx] = tf[idx] - t_there
    ok = np.zeros(len(tf), bool)
    ok[idx] = (
        (off_path <= params.path_tolerance_m)
        & (lag[idx] >= params.min_lag_s)
        & (lag[idx] <= params.max_lag_s)
        & (fleet.moving[idx] >= params.min_speed_mps)
    )
    out = []
    for a, b in _fleet_runs(fleet, ok):
        dist = float(np.sum(np.hypot(*np.diff(xy[a:b], axis=0).T)))
        if dist < params.min_distance_m:
            continue
        lags = lag[a:b]
        med = float(np.median(lags))
        tol = params.lag_tolerance * med + 1.0
        # a window's median lies between its extremes: when every lag is within the
        # tolerance, so is every running median, and it need not be computed
        if (
            np.max(np.abs(lags - med)) > tol
            and np.max(np.abs(_running_median(tf[a:b], lags, params.lag_window_s) - med)) > tol
        ):
            continue
        out.append((int(fleet.owner[a]), float(tf[a]), float(tf[b - 1]), med, dist))
    return out


def _fleet_runs(fleet: _Fleet, ok: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[start, stop)`` where ``ok`` (N,) holds, cut between trajectories."""
    before = np.concatenate([[False], ok[:-1]]) & ~fleet.first
    after = np.concatenate([ok[1:], [False]]) & ~fleet.last
    r0, r1 = np.flatnonzero(ok & ~before), np.flatnonzero(ok & ~after)
    return list(zip(r0.tolist(), (r1 + 1).tolist(), strict=True))


@dataclass(eq=False)
class _Fleet:
    """The possible followers' points end to end, for one vectorised test per leader.

    ``owner`` (N,) is each point's trajectory index; ``first`` / ``last`` (N,) mark each
    trajectory's first and last point; ``span`` maps an index to its ``[start, stop)``.
    """

    t: np.ndarray
    xy: np.ndarray
    s_m: np.ndarray
    moving: np.ndarray
    owner: np.ndarray
    first: np.ndarray
    last: np.ndarray
    span: dict[int, tuple[int, int]]

    @classmethod
    def of(cls, drives: dict[int, _Drive], members: Sequence[int]) -> _Fleet:
        parts = [drives[k] for k in members]
        sizes = np.array([len(d.t) for d in parts], int)
        stops = np.cumsum(sizes)
        starts = stops - sizes
        first = np.zeros(int(stops[-1]), bool)
        last = np.zeros(int(stops[-1]), bool)
        first[starts], last[stops - 1] = True, True
        return cls(
            np.concatenate([d.t for d in parts]),
            np.concatenate([d.p[:, :2] for d in parts]),
            np.concatenate([d.s_m for d in parts]),
            np.concatenate([d.moving for d in parts]),
            np.repeat(np.asarray(members, int), sizes),
            first,
            last,
            {k: (int(a), int(b)) for k, a, b in zip(members, starts, stops, strict=True)},
        )


def _candidates(
    leader: _Drive, fleet: _Fleet, pair_ok: np.ndarray, params: ConvoyParams
) -> np.ndarray:
    """Fleet points that could be on a convoy stretch behind ``leader``, shape (N,).

    Necessary conditions of the exact test: moving fast enough; a lag in range is possible
    (time); within the path tolerance of the box of the leader's positions at the times a
    lag in range allows (the follower's nearest point on the leader's path lies on a
    segment driven then); ``pair_ok`` (indexed by trajectory) allows the pair.
    """
    tl = leader.t
    lo_t, hi_t = params.min_lag_s - _EPS, params.max_lag_s + _EPS
    cand = (
        pair_ok[fleet.owner]
        & (fleet.moving >= params.min_speed_mps)
        & (fleet.t >= tl[0] + lo_t)
        & (fleet.t <= tl[-1] + hi_t)
    )
    sub = np.flatnonzero(cand)
    if len(sub):
        n = len(tl)
        i0 = np.clip(np.searchsorted(tl, fleet.t[sub] - hi_t, side="right") - 1, 0, n - 1)
        i1 = np.clip(np.searchsorted(tl, fleet.t[sub] - lo_t, side="left"), 0, n - 1)
        box_lo, box_hi = _range_box(leader.tables, i0, np.maximum(i0, i1))
        tol = params.path_tolerance_m + _EPS
        xy = fleet.xy[sub]
        cand[sub] = np.all((xy >= box_lo - tol) & (xy <= box_hi + tol), axis=1)
    return cand


def detect_convoys(
    trajectories: Sequence[Trajectory], params: ConvoyParams | None = None
) -> list[ActivityEvent]:
    """Groups of two or more targets driving the same path in order, steadily spaced.

    Ordered pairs (leader, follower) that cannot qualify are skipped first: a follower
    that drove less than ``min_distance_m`` in all, or whose box is more than the path
    tolerance from the leader's, or whose times cannot lag the leader's by
    ``min_lag_s`` .. ``max_lag_s``; then, per leader for all followers at once, those
    without a run of :func:`_candidates` points ``min_distance_m`` long. The events are
    exactly those of the all-pairs
    :func:`~demtrack.core.activity.reference.detect_convoys_reference`.
    """
    params = params or ConvoyParams()
    n, first_t, last_t, lo, hi = _extents(trajectories)
    valid = n >= 2
    drives = {k: _Drive.of(tr) for k, tr in enumerate(trajectories) if valid[k]}
    length = np.array([drives[k].s_m[-1] if k in drives else 0.0 for k in range(len(valid))])
    need = params.min_distance_m - _EPS * (1.0 + params.min_distance_m)
    with np.errstate(invalid="ignore"):
        cand = (  # [leader, follower]
            valid[:, None]
            & (valid & (length >= need))[None, :]
            & (_box_gaps(lo, hi) <= params.path_tolerance_m + _EPS)
            # differences of times, not sums: _EPS survives at UNIX times (1.8e9 s)
            & (last_t[None, :] - first_t[:, None] >= params.min_lag_s - _EPS)
            & (first_t[None, :] - last_t[:, None] <= params.max_lag_s + _EPS)
        )
    np.fill_diagonal(cand, False)
    pairs = []
    members = np.flatnonzero(cand.any(axis=0)).tolist()
    leaders = np.flatnonzero(cand.any(axis=1)).tolist()
    fleet = _Fleet.of(drives, members) if members else None
    for a in leaders:
        if fleet is None:  # no follower at all
            break
        ok = _candidates(drives[a], fleet, cand[a], params)
        # runs of candidates, broken where one follower's points end and the next begin
        before = np.concatenate([[False], ok[:-1]]) & ~fleet.first
        after = np.concatenate([ok[1:], [False]]) & ~fleet.last
        r0, r1 = np.flatnonzero(ok & ~before), np.flatnonzero(ok & ~after)
        long_enough = fleet.s_m[r1] - fleet.s_m[r0] >= need
        worth = np.unique(fleet.owner[r0[long_enough]])
        if not len(worth):
            continue
        # the exact test on the candidates of the followers worth it, all at once
        found = _follow_stretches(drives[a], fleet, params, ok & np.isin(fleet.owner, worth))
        for b, q0, q1, lag, dist in found:
            pairs.append((a, b, q0, q1, lag, dist))
    return convoys_of_pairs(trajectories, pairs)


def convoys_of_pairs(
    trajectories: Sequence[Trajectory],
    pairs: Sequence[tuple[int, int, float, float, float, float]],
) -> list[ActivityEvent]:
    """Join ``(leader, follower, t_start, t_end, lag_s, distance_m)`` pairs into convoys.

    Pairs that share a vehicle and overlap in time join into one convoy (a chain of
    leaders and followers), taken in order of start time. A convoy's members are in column
    order, head first (:func:`_column_order`).
    """
    ids = _ids(trajectories)
    groups: list[dict[str, Any]] = []
    for a, b, t0, t1, lag, dist in sorted(pairs, key=lambda q: q[2]):
        for g in groups:
            if ({a, b} & g["members"]) and t0 <= g["t1"] and t1 >= g["t0"]:
                g["members"] |= {a, b}
                g["t0"], g["t1"] = min(g["t0"], t0), max(g["t1"], t1)
                g["lags"].append(lag)
                g["dist"] = max(g["dist"], dist)
                g["order"].append((a, b, lag))
                break
        else:
            groups.append(
                {
                    "members": {a, b},
                    "t0": t0,
                    "t1": t1,
                    "lags": [lag],
                    "dist": dist,
                    "order": [(a, b, lag)],
                }
            )
    out = []
    for g in groups:
        order = _column_order(g["members"], g["order"])
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


def _column_order(members: set[int], edges: Sequence[tuple[int, int, float]]) -> list[int]:
    """A convoy's members in column order: by how far (s) each drives behind the head.

    ``edges``: ``(leader, follower, lag_s)``, each a measured difference of two members'
    times at the same place on the road. Every member's time behind the first is their
    least-squares fit (the group is connected: its pairs were joined by shared members),
    so a member that leads some and follows none of the others still takes its place in
    the column rather than going first. Ties (to a microsecond) go by index.
    """
    order = sorted(members)
    col = {k: i for i, k in enumerate(order)}
    a = np.zeros((len(edges) + 1, len(order)))
    rhs = np.zeros(len(edges) + 1)
    for r, (lead, follow, lag) in enumerate(edges):
        a[r, col[follow]], a[r, col[lead]], rhs[r] = 1.0, -1.0, lag
    a[-1, 0] = 1.0  # the first member's time is 0: the fit is unique
    behind = np.linalg.lstsq(a, rhs, rcond=None)[0]
    return sorted(order, key=lambda k: (round(float(behind[col[k]]), 6), k))
