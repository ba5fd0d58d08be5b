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
    a steady time lag behind (between ``min_lag_s`` and ``max_lag_s``; its running median
    over ``lag_window_s`` either side varies by at most ``lag_tolerance`` of the median lag
    + 1 s), for at least ``min_distance_m``. Pairs that share a vehicle and overlap in time
    join into one convoy.
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

from demtrack.core.activity._polyline_kernels import project_points_kernel

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


def _range_tables(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sparse tables of range maxima and minima of ``xy`` (n, 2).

    ``top[k, i]`` / ``bot[k, i]`` = max / min of ``xy[i : i + 2**k]`` (padded with -inf /
    inf past the end), shape (levels, n, 2).
    """
    n = len(xy)
    levels = max(1, int(n).bit_length())
    top = np.full((levels, n, 2), -np.inf)
    bot = np.full((levels, n, 2), np.inf)
    top[0], bot[0] = xy, xy
    for k in range(1, levels):
        h = 1 << (k - 1)
        top[k, : n - h] = np.maximum(top[k - 1, : n - h], top[k - 1, h:])
        bot[k, : n - h] = np.minimum(bot[k - 1, : n - h], bot[k - 1, h:])
    return top, bot


def _range_box(
    tables: tuple[np.ndarray, np.ndarray], i: np.ndarray, j: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes of ``xy[i..j]`` (``i <= j``, inclusive): ``lo``, ``hi`` (m, 2).

    Exact: the two power-of-two spans that cover the range only enter a max or a min.
    """
    top, bot = tables
    k = np.frexp((j - i + 1).astype(float))[1] - 1  # floor(log2(span))
    j0 = j - (1 << k) + 1
    return np.minimum(bot[k, i], bot[k, j0]), np.maximum(top[k, i], top[k, j0])


def _fits(
    tables: tuple[np.ndarray, np.ndarray], i: np.ndarray, j: np.ndarray, radius_m: float
) -> np.ndarray:
    """Whether ``xy[i..j]`` fits the disc test (half its box's diagonal <= ``radius_m``)."""
    box_lo, box_hi = _range_box(tables, i, j)
    ext = box_hi - box_lo
    return np.hypot(ext[:, 0], ext[:, 1]) / 2 <= radius_m


def _last_inside(
    xy: np.ndarray,
    radius_m: float,
    tables: tuple[np.ndarray, np.ndarray] | None = None,
    starts: np.ndarray | None = None,
    fitting: np.ndarray | None = None,
) -> np.ndarray:
    """For each point ``i`` the last ``j`` such that ``xy[i..j]`` fits the disc test.

    ``xy`` (n, 2), m. A window fits when half its bounding box's diagonal is at most
    ``radius_m``; growing a window never makes it fit, so ``j`` is found by bisection
    for all ``i`` at once, each window's box read from :func:`_range_tables`. With
    ``starts`` (m,) only those points are searched (the result has shape (m,)), from
    ``fitting`` (m,), an end known to fit for each.
    """
    n = len(xy)
    if tables is None:
        tables = _range_tables(xy)
    first = np.arange(n) if starts is None else starts
    lo = first.copy() if fitting is None else fitting.copy()
    hi = np.full(len(first), n - 1)
    while True:
        todo = np.flatnonzero(lo < hi)
        if not len(todo):
            return lo
        j = (lo[todo] + hi[todo] + 1) // 2
        fits = _fits(tables, first[todo], j, radius_m)
        lo[todo] = np.where(fits, j, lo[todo])
        hi[todo] = np.where(fits, hi[todo], j - 1)


def _first_lasting(t: np.ndarray, min_duration_s: float) -> np.ndarray:
    """For each ``i`` the first ``j`` with ``t[j] - t[i] >= min_duration_s``, or ``n``.

    ``t`` (n,) non-decreasing (s). The differences are computed as the test writes them
    (a rounded ``t[i] + min_duration_s`` is only the first guess): ``t[j] - t[i]`` never
    decreases with ``j``, so stepping forward from a guess at or before the answer finds it.
    """
    n = len(t)
    slack = 1e-9 * (np.abs(t) + abs(min_duration_s) + 1.0)
    j = np.minimum(np.searchsorted(t, t + min_duration_s - slack, side="left"), n)
    j = np.maximum(j, np.arange(n))
    while True:
        short = np.flatnonzero(j < n)
        short = short[t[j[short]] - t[short] < min_duration_s]
        if not len(short):
            return j
        j[short] += 1


def _loiter_ends(t: np.ndarray, xy: np.ndarray, params: LoiterParams) -> np.ndarray:
    """Per point ``i``, :func:`_last_inside` where that window lasts ``min_duration_s``, else -1.

    The same answer as ``_last_inside(xy)`` masked by ``t[end] - t >= min_duration_s``:
    fitting is monotone, so ``i`` qualifies exactly when its shortest lasting window
    ``xy[i..j]`` fits; only the points that qualify are bisected further.
    """
    n = len(t)
    out = np.full(n, -1)
    j = _first_lasting(t, params.min_duration_s)
    i = np.flatnonzero(j < n)
    if not len(i):
        return out
    tables = _range_tables(xy)
    # (a window of one point lasts 0 s: it qualifies as the old test had it, fit or not)
    i = i[_fits(tables, i, j[i], params.radius_m) | (j[i] == i)]
    if not len(i):
        return out
    out[i] = _last_inside(xy, params.radius_m, tables, i, j[i])
    return out


def detect_loitering(
    trajectories: Sequence[Trajectory], params: LoiterParams | None = None
) -> list[ActivityEvent]:
    """Episodes where a target stays within ``radius_m`` for ``min_duration_s`` or longer."""
    params = params or LoiterParams()
    out = []
    for tid, tr in zip(_ids(trajectories), trajectories, strict=True):
        t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
        n = len(t)
        if n == 0:
            continue
        best_end = _loiter_ends(t, p[:, :2], params)
        qualifies = best_end >= 0
        # a point is covered when some qualifying window starting at or before it reaches it
        covered = np.maximum.accumulate(np.where(qualifies, best_end, -1)) >= np.arange(n)
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


def _resample(tr: Trajectory, grid: np.ndarray, dims: int = 3, first: int = 0) -> np.ndarray:
    """Columns ``first .. first + dims - 1`` of the positions at times ``grid``, linearly."""
    t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
    return np.column_stack([np.interp(grid, t, p[:, k]) for k in range(first, first + dims)])


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


def _speed(p: np.ndarray, dt: float) -> np.ndarray:
    """Horizontal speed at each of ``p`` (n, 3) sampled every ``dt`` (s), m/s.

    ``np.gradient(p[:, :2], dt, axis=0)`` written out (the same arithmetic: central
    differences inside, one-sided at the ends), without its per-call overhead.
    """
    if len(p) < 2:
        return np.zeros(len(p))
    xy = p[:, :2]
    v = np.empty((len(p), 2))
    v[1:-1] = (xy[2:] - xy[:-2]) / (2.0 * dt)
    v[0] = (xy[1] - xy[0]) / dt
    v[-1] = (xy[-1] - xy[-2]) / dt
    return np.hypot(v[:, 0], v[:, 1])


#: Slack on the exact tests' thresholds in the cheap prefilters (m, s): a pair or a point
#: is skipped only when it misses a necessary condition by more than rounding could explain.
_EPS = 1e-6


def _extents(trajectories: Sequence[Trajectory]) -> tuple[np.ndarray, ...]:
    """Per trajectory: point count, first and last time, horizontal bounding box.

    Returns ``n`` (m,), ``t0``, ``t1`` (m,) in s, ``lo``, ``hi`` (m, 2) in m (NaN when empty).
    """
    m = len(trajectories)
    n = np.zeros(m, int)
    t0, t1 = np.full(m, np.nan), np.full(m, np.nan)
    lo, hi = np.full((m, 2), np.nan), np.full((m, 2), np.nan)
    for k, tr in enumerate(trajectories):
        t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
        n[k] = len(t)
        if len(t):
            t0[k], t1[k] = t[0], t[-1]
            lo[k], hi[k] = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    return n, t0, t1, lo, hi


def _box_gaps(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Horizontal distance between every two bounding boxes, shape (m, m) (m)."""
    gap = np.maximum(lo[:, None, :] - hi[None, :, :], lo[None, :, :] - hi[:, None, :])
    return np.hypot(*np.maximum(gap, 0.0).transpose(2, 0, 1))


def detect_rendezvous(
    trajectories: Sequence[Trajectory], params: RendezvousParams | None = None
) -> list[ActivityEvent]:
    """Pairs of targets stopped together for at least ``min_duration_s``.

    Pairs that cannot qualify are skipped before the test on the common time grid: those
    that share less than ``min_duration_s`` or whose bounding boxes lie more than
    ``distance_m`` apart (positions on the grid lie inside each path's box). The events
    are exactly those of the all-pairs
    :func:`~demtrack.core.activity.reference.detect_rendezvous_reference`.
    """
    params = params or RendezvousParams()
    ids = _ids(trajectories)
    n, t0, t1, lo, hi = _extents(trajectories)
    valid = n >= 2
    with np.errstate(invalid="ignore"):
        shared = np.minimum(t1[:, None], t1[None, :]) - np.maximum(t0[:, None], t0[None, :])
        near = _box_gaps(lo, hi) <= params.distance_m + _EPS
    cand = np.triu(valid[:, None] & valid[None, :] & near & (shared >= params.min_duration_s), 1)
    pairs, grids = [], []
    for a, b in zip(*np.nonzero(cand), strict=True):
        ta, tb = trajectories[a].t_s, trajectories[b].t_s
        lo_t, hi_t = max(ta[0], tb[0]), min(ta[-1], tb[-1])
        if hi_t - lo_t < params.min_duration_s:
            continue
        grid = np.arange(lo_t, hi_t + 1e-9, params.dt_s)
        if len(grid):
            pairs.append((int(a), int(b)))
            grids.append(grid)
    out = []
    for (a, b), grid, any_close in zip(
        pairs, grids, _ever_close(trajectories, pairs, grids, params.distance_m), strict=True
    ):
        # the horizontal test first: most pairs are never close, and their heights unread
        if not any_close:
            continue
        xa, xb = _resample(trajectories[a], grid, 2), _resample(trajectories[b], grid, 2)
        close = np.hypot(*(xa - xb).T) <= params.distance_m
        pa = np.column_stack([xa, _resample(trajectories[a], grid, 1, 2)])
        pb = np.column_stack([xb, _resample(trajectories[b], grid, 1, 2)])
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
                        (ids[int(a)], ids[int(b)]),
                        mid,
                        {"mean_distance_m": gap, "duration_s": float(grid[e - 1] - grid[s])},
                    )
                )
    return out


def _ever_close(
    trajectories: Sequence[Trajectory],
    pairs: Sequence[tuple[int, int]],
    grids: Sequence[np.ndarray],
    distance_m: float,
) -> np.ndarray:
    """Per pair ``(a, b)``, whether the two are ever within ``distance_m`` on its grid.

    The rendezvous test's horizontal condition for all pairs at once, bit for bit: each
    trajectory is resampled (:func:`_resample`, pointwise) once, at the grids of all its
    pairs end to end, instead of once per pair. Every grid holds a point.
    """
    if not pairs:
        return np.zeros(0, bool)
    sizes = np.array([len(g) for g in grids])
    starts = np.cumsum(sizes) - sizes
    # every (pair, side) use of a trajectory, grouped by trajectory (pair order within)
    owner = np.asarray(pairs).T.ravel()  # side 0 of every pair, then side 1
    use = np.argsort(owner, kind="stable")
    pair, side = use % len(pairs), use // len(pairs)
    # the uses' grid points end to end, and where each goes in ``at``
    query = np.concatenate([grids[i] for i in pair.tolist()])
    n_use = sizes[pair]
    where = np.arange(len(query)) - np.repeat(np.cumsum(n_use) - n_use - starts[pair], n_use)
    side = np.repeat(side, n_use)
    cut = np.concatenate([[0], np.cumsum(n_use)])
    bounds = np.flatnonzero(np.diff(owner[use])) + 1  # first use of each next trajectory
    first_use = np.concatenate([[0], bounds]).tolist()
    last_use = np.concatenate([bounds, [len(use)]]).tolist()
    at = np.empty((2, int(sizes.sum()), 2))  # side, grid point, (x, y)
    for u0, u1 in zip(first_use, last_use, strict=True):
        q = slice(int(cut[u0]), int(cut[u1]))
        at[side[q], where[q]] = _resample(trajectories[int(owner[use[u0]])], query[q], 2)
    close = np.hypot(*(at[0] - at[1]).T) <= distance_m
    return np.logical_or.reduceat(close, starts)


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
    ids = _ids(trajectories)
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
            & (last_t[None, :] >= first_t[:, None] + params.min_lag_s - _EPS)
            & (first_t[None, :] <= last_t[:, None] + params.max_lag_s + _EPS)
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
