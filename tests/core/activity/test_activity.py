from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import shapely

from demtrack.core.activity.convoy import ConvoyParams, detect_convoys
from demtrack.core.activity.loitering import LoiterParams, detect_loitering
from demtrack.core.activity.rendezvous import RendezvousParams, detect_rendezvous
from demtrack.core.activity.zones import Zone, detect_zone_crossings


@dataclass
class Path:
    id: int
    t_s: np.ndarray
    p_enu: np.ndarray


def walk(tid, waypoints, speeds, t0=0.0, dt=0.5, pauses=None, jitter=0.0, seed=0):
    """Piecewise-linear path through ``waypoints`` at ``speeds`` (one per leg), pausing
    ``pauses[k]`` seconds at waypoint k; positions sampled every ``dt`` with jitter."""
    rng = np.random.default_rng(seed)
    pauses = pauses or {}
    times, pts = [t0], [np.asarray(waypoints[0], float)]
    for k, (a, b) in enumerate(zip(waypoints[:-1], waypoints[1:], strict=True)):
        if pauses.get(k, 0) > 0:
            times.append(times[-1] + pauses[k])
            pts.append(np.asarray(a, float))
        times.append(times[-1] + np.hypot(*(np.subtract(b, a))) / speeds[k])
        pts.append(np.asarray(b, float))
    times, pts = np.array(times), np.array(pts)
    t = np.arange(times[0], times[-1], dt)
    xy = np.column_stack([np.interp(t, times, pts[:, 0]), np.interp(t, times, pts[:, 1])])
    xy += rng.normal(0, jitter, xy.shape)
    return Path(tid, t, np.column_stack([xy, np.zeros(len(t))]))


def test_loitering_fires_once_for_a_long_stop_and_not_for_a_short_one():
    person = walk(1, [(0, 0), (70, 0), (140, 0)], [1.4, 1.4], pauses={1: 90.0}, jitter=0.5)
    brief = walk(2, [(0, 10), (70, 10), (140, 10)], [1.4, 1.4], pauses={1: 40.0}, jitter=0.5)
    events = detect_loitering([person, brief], LoiterParams(radius_m=5.0, min_duration_s=60.0))
    assert [e.track_ids for e in events] == [(1,)]
    (e,) = events
    # The stop runs 50 s .. 140 s; the disc also catches the approach and departure
    # within 5 m (about 3.6 s each way at 1.4 m/s).
    assert e.t_start_s == pytest.approx(50.0 - 5.0 / 1.4, abs=2.0)
    assert e.t_end_s == pytest.approx(140.0 + 5.0 / 1.4, abs=2.0)
    assert np.hypot(*(e.p_enu[:2] - [70.0, 0.0])) < 1.0
    # The episode is the union of qualifying windows: a little wider than one disc.
    assert e.details["extent_radius_m"] < 2 * 5.0


def test_slow_walk_around_a_large_circle_is_not_loitering():
    th = np.linspace(0, 2 * np.pi, 400)
    circle = Path(3, th * 30 / 0.5, np.column_stack([30 * np.cos(th), 30 * np.sin(th), 0 * th]))
    assert detect_loitering([circle], LoiterParams(radius_m=10.0, min_duration_s=60.0)) == []


def test_rendezvous_needs_both_close_and_stopped_long_enough():
    a = walk(1, [(-50, 0), (-1, 0), (-50, 0)], [1.5, 1.5], pauses={1: 40.0})
    b = walk(2, [(50, 0), (1, 0), (50, 0)], [1.5, 1.5], pauses={1: 40.0})
    passing = walk(3, [(-50, 20), (50, 20)], [1.5])
    passing2 = walk(4, [(50, 20.5), (-50, 20.5)], [1.5])
    far = walk(5, [(0, 60), (0, 61)], [0.01])  # stands still, 60 m away
    params = RendezvousParams(distance_m=5.0, min_duration_s=20.0)
    events = detect_rendezvous([a, b, passing, passing2, far], params)
    assert [e.track_ids for e in events] == [(1, 2)]
    (e,) = events
    assert e.details["mean_distance_m"] == pytest.approx(2.0, abs=0.3)
    assert 35.0 <= e.details["duration_s"] <= 42.0


ROAD = [(0, 0), (200, 0), (300, 100), (300, 300)]


def test_convoy_of_three_in_order_and_near_misses_stay_out():
    lead = walk(10, ROAD, [10.0] * 3, t0=0.0)
    second = walk(11, ROAD, [10.0] * 3, t0=3.0)
    third = walk(12, ROAD, [10.0] * 3, t0=6.5)
    oncoming = walk(13, ROAD[::-1], [10.0] * 3, t0=0.0)
    much_later = walk(14, ROAD, [10.0] * 3, t0=200.0)
    events = detect_convoys([lead, second, third, oncoming, much_later], ConvoyParams())
    assert len(events) == 1
    (e,) = events
    assert e.track_ids == (10, 11, 12)
    assert sorted(round(x, 1) for x in e.details["lags_s"]) == pytest.approx(
        [3.0, 3.5, 6.5], abs=0.6
    )
    assert e.details["distance_m"] > 300


def test_following_for_a_short_distance_is_not_a_convoy():
    lead = walk(1, ROAD, [10.0] * 3)
    joins_late = walk(2, [(300, 200), (300, 300)], [10.0], t0=lead.t_s[-1] - 7.0)
    assert detect_convoys([lead, joins_late], ConvoyParams(min_distance_m=150.0)) == []


# East, a loop to the north, then south across the first leg at (20, 0).
CROSSING = [(-100.8, 0), (50, 0), (50, 20), (20, 20), (20, -100)]


def test_convoy_across_its_own_path_is_steady():
    # The follower keeps 3 s behind, 0.3 m east and 0.2 m north of the leader's line. Its
    # fix at the crossing, (20.3, 0.2) on the southbound leg, lies 0.2 m from the leader's
    # eastbound pass and 0.3 m from its southbound one: the nearest point of the path is
    # on the wrong pass, 12.5 s earlier, and that one fix's lag is 15.5 s.
    lead = walk(1, CROSSING, [8.0] * 4, dt=0.2)
    follow = walk(2, CROSSING, [8.0] * 4, t0=3.0, dt=0.2)
    follow.p_enu[:, :2] += (0.3, 0.2)
    (e,) = detect_convoys([lead, follow])
    assert e.track_ids == (1, 2)
    assert e.details["lags_s"] == [pytest.approx(3.0, abs=0.1)]
    assert e.details["distance_m"] > 300
    # Read pointwise (no running median), that one fix breaks the whole 320 m stretch.
    assert detect_convoys([lead, follow], ConvoyParams(lag_window_s=0.0)) == []


def test_zone_entry_and_exit_times_are_interpolated_to_the_boundary():
    zone = Zone("gate", shapely.box(40, -5, 60, 5))
    car = walk(7, [(0, 0), (100, 0)], [10.0], dt=1.0)
    events = detect_zone_crossings([car], [zone])
    assert [(e.kind, e.details["zone"]) for e in events] == [
        ("zone-enter", "gate"),
        ("zone-leave", "gate"),
    ]
    assert events[0].t_start_s == pytest.approx(4.0)
    assert events[1].t_start_s == pytest.approx(6.0)
    np.testing.assert_allclose(events[0].p_enu, [40.0, 0.0, 0.0])
    assert events[0].to_dict()["track_ids"] == [7]
