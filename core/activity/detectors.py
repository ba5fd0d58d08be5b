"""What every activity detector shares: the trajectory protocol, the event, array helpers.

Collins et al. (1998) geolocate targets so that behaviour can be reasoned about in one
geospatial frame. The detectors (``core.activity.loitering``, ``.rendezvous``, ``.convoy``,
``.zones``) read any trajectory with ``id``, ``cls``, ``t_s`` (n,) and ``p_enu`` (n, 3) in
the site frame (tracks from the tracker, or ground-truth paths) and return
:class:`ActivityEvent` values. Every threshold is a parameter with a physical meaning;
defaults suit people and cars on a site of a few hundred metres. The helpers here
(resampling, speeds, extents, running range tables) serve more than one detector.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

__all__ = [
    "ActivityEvent",
    "Trajectory",
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


def _resample(tr: Trajectory, grid: np.ndarray, dims: int = 3, first: int = 0) -> np.ndarray:
    """Columns ``first .. first + dims - 1`` of the positions at times ``grid``, linearly."""
    t, p = np.asarray(tr.t_s, float), np.asarray(tr.p_enu, float)
    return np.column_stack([np.interp(grid, t, p[:, k]) for k in range(first, first + dims)])


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
