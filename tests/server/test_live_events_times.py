"""LiveEvents reads each track's times once: revised tails and replaced points are re-read."""

from __future__ import annotations

import numpy as np

from demtrack.core.tracking.types import Track, TrackPoint
from demtrack.server.live_events import LiveEventParams, LiveEvents


def point(t: float, x: float = 0.0) -> TrackPoint:
    return TrackPoint(t, np.array([x, 0.0, 0.0]), ("cam1",), ())


def test_times_follow_revisions_appends_and_replaced_points():
    live = LiveEvents(None, LiveEventParams())  # type: ignore[arg-type]  # no site needed
    pts = tuple(point(0.1 * k) for k in range(50))
    first = Track(1, "vehicle", pts)
    assert np.array_equal(live._times(first), first.t_s)
    assert live._times(first) is live._times(first)  # the same track: not read again
    # the smoother revises the last 5 points (new objects, new times) and 10 are appended
    revised = pts[:45] + tuple(point(0.1 * k + 0.01) for k in range(45, 60))
    second = Track(1, "vehicle", revised)
    assert np.array_equal(live._times(second), second.t_s)
    # an earlier point replaced while the tail is kept: everything is read again
    odd = revised[:10] + (point(1.05),) + revised[11:]
    third = Track(1, "vehicle", odd)
    assert np.array_equal(live._times(third), third.t_s)
    # the id now names another track (fewer points, none shared)
    other = Track(1, "human", tuple(point(5.0 + k) for k in range(3)))
    assert np.array_equal(live._times(other), other.t_s)
