"""Rendezvous: two targets close together while both are stopped, for ``min_duration_s``.

Two targets are within ``distance_m`` of each other while both are stopped (speed below
``stop_speed_mps``) for at least ``min_duration_s``. Pairs that can never meet (their
extents apart, or never close on a coarse grid) are skipped before the exact test.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .detectors import (
    _EPS,
    ActivityEvent,
    Trajectory,
    _box_gaps,
    _extents,
    _ids,
    _resample,
    _runs,
    _speed,
)

__all__ = [
    "RendezvousParams",
    "detect_rendezvous",
]


@dataclass(frozen=True)
class RendezvousParams:
    """Rendezvous: within ``distance_m``, both slower than ``stop_speed_mps``, for a while."""

    distance_m: float = 5.0
    stop_speed_mps: float = 0.5
    min_duration_s: float = 20.0
    dt_s: float = 1.0


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
        # From the pair's start, not from t = 0: at UNIX times (1.8e9 s) a 1e-9 s slack
        # added to hi_t is below float64's grain and the last sample would come and go.
        grid = lo_t + np.arange(0.0, hi_t - lo_t + 1e-9, params.dt_s)
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
