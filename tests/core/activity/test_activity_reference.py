"""The optimised detectors return exactly the events of their straightforward twins."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pytest

from demtrack.core.activity.convoy import ConvoyParams, detect_convoys
from demtrack.core.activity.detectors import ActivityEvent
from demtrack.core.activity.loitering import LoiterParams, detect_loitering
from demtrack.core.activity.reference import (
    detect_convoys_reference,
    detect_loitering_reference,
    detect_rendezvous_reference,
)
from demtrack.core.activity.rendezvous import RendezvousParams, detect_rendezvous
from demtrack.samplesite.activity_scenarios import ACTIVITY_CASES, truth_paths
from demtrack.samplesite.world import make_world


@dataclass
class Path:
    id: int
    cls: str
    t_s: np.ndarray
    p_enu: np.ndarray


def as_tuples(events: list[ActivityEvent]) -> list[tuple]:
    """Everything an event says, exactly (no tolerance: the results must be identical)."""
    return [
        (e.kind, e.t_start_s, e.t_end_s, e.track_ids, tuple(e.p_enu.tolist()), repr(e.details))
        for e in events
    ]


def route(rng: np.random.Generator, n_legs: int = 6) -> np.ndarray:
    """A random polyline on a 300 m site (waypoints, m)."""
    return np.cumsum(rng.uniform(-60, 60, (n_legs + 1, 2)), axis=0) + rng.uniform(-100, 100, 2)


def drive(tid, cls, waypoints, speed, t0, dt, rng, jitter=0.5, stop=None):
    """Follow ``waypoints`` at ``speed`` from ``t0``, sampled every ``dt`` (with jitter);
    ``stop = (leg, seconds)`` pauses at the start of that leg."""
    seg = np.hypot(*np.diff(waypoints, axis=0).T)
    times = [t0]
    pts = [waypoints[0]]
    for k, length in enumerate(seg):
        if stop is not None and stop[0] == k:
            times.append(times[-1] + stop[1])
            pts.append(waypoints[k])
        times.append(times[-1] + length / speed)
        pts.append(waypoints[k + 1])
    times_a, pts_a = np.array(times), np.array(pts)
    t = np.arange(t0, times_a[-1], dt) + rng.uniform(0, 0.3 * dt, 1)
    t = t[t <= times_a[-1]]
    xy = np.column_stack([np.interp(t, times_a, pts_a[:, k]) for k in range(2)])
    xy += rng.normal(0, jitter, xy.shape)
    return Path(tid, cls, t, np.column_stack([xy, rng.normal(0, 0.1, len(t))]))


def random_scene(seed: int) -> list[Path]:
    """Convoys (2-3 cars on one route, various lags and speeds), cars crossing, people
    stopping near each other or not, stationary false tracks, a one-point track and a
    track with a repeated time."""
    rng = np.random.default_rng(seed)
    out: list[Path] = []
    for _ in range(3):
        way = route(rng)
        t0 = rng.uniform(0, 60)
        for k in range(int(rng.integers(1, 4))):
            speed = rng.uniform(4, 12) * (1 if rng.random() < 0.7 else rng.uniform(0.4, 1))
            t_k = t0 + k * rng.uniform(1, 8)
            out.append(drive(len(out) + 1, "vehicle", way, speed, t_k, 0.5, rng))
    for _ in range(4):
        out.append(
            drive(
                len(out) + 1,
                "vehicle",
                route(rng, 3),
                rng.uniform(3, 12),
                rng.uniform(0, 80),
                0.5,
                rng,
            )
        )
    meet = rng.uniform(-50, 50, 2)
    for _ in range(4):
        start = meet + rng.uniform(-40, 40, 2)
        end = meet + rng.uniform(-40, 40, 2)
        stop_at = meet + rng.uniform(-4, 4, 2)
        way = np.array([start, stop_at, end])
        out.append(
            drive(
                len(out) + 1,
                "human",
                way,
                1.4,
                rng.uniform(0, 20),
                0.5,
                rng,
                jitter=0.2,
                stop=(1, rng.uniform(10, 60)),
            )
        )
    for _ in range(2):
        p = rng.uniform(-100, 100, 2)
        out.append(drive(len(out) + 1, "vehicle", np.array([p, p + 0.5]), 0.01, 0.0, 0.5, rng))
    out.append(Path(len(out) + 1, "vehicle", np.array([3.0]), np.zeros((1, 3))))
    rep = drive(len(out) + 1, "vehicle", route(rng, 2), 8.0, 5.0, 0.5, rng)
    rep.t_s[5] = rep.t_s[4]  # a repeated time, as a fused track can have
    out.append(rep)
    return out


LOOSE_CONVOY = ConvoyParams(min_distance_m=40.0, lag_tolerance=2.0, path_tolerance_m=8.0)
LOOSE_MEET = RendezvousParams(distance_m=10.0, min_duration_s=8.0)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("loose", [False, True])
def test_pruned_detectors_match_all_pairs_on_random_scenes(seed, loose):
    paths = random_scene(seed)
    cp = LOOSE_CONVOY if loose else ConvoyParams()
    rp = LOOSE_MEET if loose else RendezvousParams()
    assert as_tuples(detect_convoys(paths, cp)) == as_tuples(detect_convoys_reference(paths, cp))
    assert as_tuples(detect_rendezvous(paths, rp)) == as_tuples(
        detect_rendezvous_reference(paths, rp)
    )


def test_random_scenes_hold_events_of_both_kinds():
    """The comparison above compares something: the scenes do have convoys and meetings."""
    convoys = rendezvous = 0
    for seed in range(8):
        paths = random_scene(seed)
        convoys += len(detect_convoys_reference(paths, LOOSE_CONVOY))
        rendezvous += len(detect_rendezvous_reference(paths, LOOSE_MEET))
    assert convoys >= 4
    assert rendezvous >= 4


def test_pruned_detectors_match_all_pairs_on_the_activity_cases():
    world = make_world(7)
    paths = []
    for make in ACTIVITY_CASES.values():
        for tr in truth_paths(make(world), world, dt_s=0.2):
            paths.append(Path(len(paths) + 1, tr.cls, tr.t_s, tr.p_enu))
    found = 0
    for cp, rp in [(ConvoyParams(), RendezvousParams()), (LOOSE_CONVOY, LOOSE_MEET)]:
        conv = detect_convoys(paths, cp)
        meet = detect_rendezvous(paths, rp)
        assert as_tuples(conv) == as_tuples(detect_convoys_reference(paths, cp))
        assert as_tuples(meet) == as_tuples(detect_rendezvous_reference(paths, rp))
        found += len(conv) + len(meet)
    assert found >= 4


@pytest.mark.parametrize("seed", range(8))
def test_bisected_loitering_matches_the_two_pointer_walk(seed):
    paths = random_scene(seed)
    rng = np.random.default_rng(seed)
    for radius, dwell in [(10.0, 60.0), (5.0, 20.0), (30.0, 10.0)]:
        prm = LoiterParams(radius_m=radius, min_duration_s=dwell)
        assert as_tuples(detect_loitering(paths, prm)) == as_tuples(
            detect_loitering_reference(paths, prm)
        )
    # a random walk that wanders in and out of the disc test many times
    t = np.arange(2000) * 0.5
    xy = np.cumsum(rng.normal(0, 0.8, (2000, 2)), axis=0)
    walker = [Path(1, "human", t, np.column_stack([xy, np.zeros(2000)]))]
    prm = LoiterParams(radius_m=6.0, min_duration_s=30.0)
    assert len(detect_loitering_reference(walker, prm)) >= 2
    assert as_tuples(detect_loitering(walker, prm)) == as_tuples(
        detect_loitering_reference(walker, prm)
    )


def test_convoy_of_tracks_with_repeated_times_needs_no_division_by_zero():
    """Fused tracks hold one point per camera's fix: when most points share a time with
    the next, the median step is 0; the speed uses the positive steps instead (it was
    0/0, numpy's "invalid value encountered in divide", and every moved point counted
    as moving)."""
    rng = np.random.default_rng(3)
    way = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0]])
    cars = []
    for k, t0 in enumerate([0.0, 4.0]):
        car = drive(k + 1, "vehicle", way, 8.0, t0, 0.2, rng, jitter=0.2)
        # each time twice (two cameras' fixes), the second a little apart
        t = np.repeat(car.t_s, 2)
        p = np.repeat(car.p_enu, 2, axis=0) + rng.normal(0, 0.05, (2 * len(car.t_s), 3))
        cars.append(Path(k + 1, "vehicle", t, p))
    assert np.median(np.diff(cars[0].t_s)) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = detect_convoys(cars)
        assert as_tuples(found) == as_tuples(detect_convoys_reference(cars))
    assert [e.track_ids for e in found] == [(1, 2)]
    assert np.median(found[0].details["lags_s"]) == pytest.approx(4.0, abs=0.5)


def test_running_median_matches_one_window_at_a_time():
    """The lag's running median (``lag_window_s`` either side), vectorised, against a loop,
    on irregular times with repeats (fused tracks) and windows cut at the ends."""
    from demtrack.core.activity.convoy import _running_median

    rng = np.random.default_rng(5)
    t = np.sort(np.round(rng.uniform(0, 20, 120), 1))  # rounding repeats some times
    x = rng.normal(3.0, 1.0, len(t))
    for half in (0.0, 0.3, 1.0, 50.0):
        loop = [np.median(x[(t >= ti - half) & (t <= ti + half)]) for ti in t]
        np.testing.assert_array_equal(_running_median(t, x, half), loop)
    alone = np.ones(len(t), bool)
    alone[1:] &= np.diff(t) > 0
    alone[:-1] &= np.diff(t) > 0
    assert alone.any() and not alone.all()
    np.testing.assert_array_equal(_running_median(t, x, 0.0)[alone], x[alone])


@pytest.mark.parametrize("seed", range(4))
def test_pruned_convoys_match_all_pairs_where_the_route_crosses_itself(seed):
    """A route that loops back across itself (the nearest point of the leader's path to a
    fix near the crossing can be the other pass), cars at various lags, with jitter."""
    rng = np.random.default_rng(seed)
    way = np.array([[-100.0, 0.0], [50.0, 0.0], [50.0, 20.0], [20.0, 20.0], [20.0, -100.0]])
    way += rng.uniform(-50, 50, 2)
    cars = [
        drive(k + 1, "vehicle", way, 8.0, t0, 0.2, rng, jitter=0.3)
        for k, t0 in enumerate(np.cumsum(rng.uniform(1.0, 6.0, 3)))
    ]
    for cp in (ConvoyParams(), ConvoyParams(lag_window_s=0.0), LOOSE_CONVOY):
        assert as_tuples(detect_convoys(cars, cp)) == as_tuples(detect_convoys_reference(cars, cp))
    assert [len(e.track_ids) for e in detect_convoys(cars)] == [3]


@pytest.mark.parametrize("seed", range(4))
def test_loitering_on_repeated_and_large_times_matches_the_two_pointer_walk(seed):
    """The shortest lasting window is found from a rounded guess of ``t + min_duration_s``:
    times far from 0, repeated times and durations that land exactly on a later time are
    where the guess and the test's own ``t[j] - t[i]`` could disagree."""
    rng = np.random.default_rng(seed)
    n = 1500
    steps = rng.choice([0.0, 0.1, 0.1, 0.3], n)
    t = 86_400.0 * (seed + 1) + np.cumsum(steps)
    xy = np.cumsum(rng.normal(0, 0.4, (n, 2)), axis=0)
    walker = [Path(1, "human", t, np.column_stack([xy, np.zeros(n)]))]
    found = 0
    for radius, dwell in [(3.0, 6.0), (4.0, 0.3), (2.0, 0.0), (5.0, 12.1)]:
        prm = LoiterParams(radius_m=radius, min_duration_s=dwell)
        ref = detect_loitering_reference(walker, prm)
        assert as_tuples(detect_loitering(walker, prm)) == as_tuples(ref)
        found += len(ref)
    assert found >= 2
