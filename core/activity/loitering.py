"""Loitering: a target stays inside a disc of radius ``radius_m`` for ``min_duration_s``.

Tested on the window's bounding box: half its diagonal at most ``radius_m``. Windows are
found with running range tables (``core.activity.detectors``), not by scanning every pair.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .detectors import ActivityEvent, Trajectory, _ids, _range_box, _range_tables, _runs

__all__ = [
    "LoiterParams",
    "detect_loitering",
]


@dataclass(frozen=True)
class LoiterParams:
    """Loitering: inside a disc of ``radius_m`` for at least ``min_duration_s``."""

    radius_m: float = 10.0
    min_duration_s: float = 60.0


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
