"""Settled-confirmation initiator, road-following prediction and re-acquisition."""

import math

import numpy as np
import pytest
from shapely import LineString

from demtrack.core.errors import TrackingError
from demtrack.core.tracking import TrackerConfig, run_tracker
from demtrack.core.tracking.initiation import MOfNInitiator, spread_m
from demtrack.core.tracking.kalman import GaussianState, KalmanFilter
from demtrack.core.tracking.motion import ConstantVelocity
from demtrack.core.tracking.reacquire import (
    MotionReacquirer,
    RoadFollowingReacquirer,
    gaussian_density,
)
from demtrack.core.tracking.roadfollow import follow_road
from demtrack.core.tracking.types import Fix


# -------------------------------------------------------------------- initiator
def test_spread_is_the_worst_direction_sigma():
    assert spread_m(np.diag([16.0, 1.0])) == pytest.approx(4.0)
    c, s = math.cos(0.7), math.sin(0.7)
    r = np.array([[c, -s], [s, c]])
    assert spread_m(r @ np.diag([9.0, 0.25]) @ r.T) == pytest.approx(3.0)


def test_confirmation_needs_m_fixes_and_a_settled_position():
    ini = MOfNInitiator(3, 1.0, True, max_spread_m=1.5, settle_window_s=5.0)
    assert not ini.confirmed(2, 0.2, 0.5)  # too few fixes
    assert not ini.confirmed(3, 0.3, 2.0)  # enough fixes, still spread out
    assert ini.confirmed(3, 0.3, 1.5) and ini.confirmed(9, 3.0, 0.1)
    # never settled: confirmed anyway once the settle window is over
    assert not ini.confirmed(40, 4.9, 2.0) and ini.confirmed(40, 5.0, 2.0)
    # fewer than m fixes within the window: dropped; m fixes: kept while settling
    assert ini.expired(2, 1.01) and not ini.expired(2, 0.99)
    assert not ini.expired(5, 4.9) and not ini.expired(5, 50.0)
    # the points before the state first settled are left out
    assert ini.reportable([4.0, 3.0, 1.4, 2.0, 1.0]) == 2
    assert ini.reportable([0.5]) == 0 and ini.reportable([3.0, 3.0]) == 2


def test_plain_m_of_n_ignores_the_spread():
    ini = MOfNInitiator(3, 1.0)
    assert ini.confirmed(3, 0.3, 100.0) and ini.reportable([9.0, 9.0, 9.0]) == 0
    assert not ini.expired(3, 100.0)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"m": 0},
        {"window_s": 0.0},
        {"max_spread_m": 0.0},
        {"max_spread_m": float("nan")},
        {"settle_window_s": 0.5},
    ],
)
def test_initiator_rejects_bad_settings(kwargs):
    with pytest.raises(TrackingError):
        MOfNInitiator(**kwargs)


def _along_ray_fixes(seed: int, sigma_along: float = 3.0) -> tuple[list[Fix], float]:
    """One far camera looking along a road; the car drives along x at 8 m/s, 10 Hz.

    Each fix has one hit, 3 m 1-sigma along the ray (x) and 0.3 m across it.
    """
    rng = np.random.default_rng(seed)
    cov = np.diag([sigma_along**2, 0.3**2])
    fixes = []
    for k in range(60):
        t = 0.1 * k
        p = np.array([8.0 * t, 0.0, 0.0])
        hit = p + np.array([rng.normal(0, sigma_along), rng.normal(0, 0.3), 0.0])
        origin = np.array([300.0, 0.0, 30.0])
        fixes.append(
            Fix(
                t,
                "far",
                "vehicle",
                k,
                origin,
                hit - origin,
                hit[None],
                [sigma_along],
                hit_cov_en_m2=cov[None],
            )  # fmt: skip
        )
    return fixes, 8.0


def _track(fixes: list[Fix], spread: float | None):
    cfg = TrackerConfig(confirm_spread_m=spread, fuse_sensors=False)
    (track,) = run_tracker(fixes, "kalman", config=cfg)
    return track


def _worst(track, speed: float) -> float:
    return float(np.abs(track.p_enu[:, 0] - speed * track.t_s).max())


def test_a_track_is_reported_only_once_its_position_has_settled():
    fixes, _ = _along_ray_fixes(0, sigma_along=3.5)
    assert _track(fixes, None).t_s[0] == 0.0  # plain M-of-N: from the first fix
    settled = _track(fixes, 1.5)
    assert settled.t_s[0] > 1.0
    assert spread_m(settled.points[0].cov_xy) <= 1.5


def test_settled_tracks_start_closer_to_the_truth():
    plain, settled = [], []
    for seed in range(4):
        fixes, speed = _along_ray_fixes(seed, sigma_along=4.0)
        plain.append(_worst(_track(fixes, None), speed))
        settled.append(_worst(_track(fixes, 1.5), speed))
    assert max(settled) < min(plain)


def test_an_object_that_never_settles_is_still_reported_after_the_settle_window():
    fixes, _ = _along_ray_fixes(0, sigma_along=8.0)
    track = _track(fixes, 1.5)
    assert 4.5 <= track.t_s[0] <= 5.1
    assert spread_m(track.points[0].cov_xy) > 1.5


# ----------------------------------------------------------------- road follow
def _circle(radius: float = 50.0, n: int = 720) -> LineString:
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    xy = np.column_stack([radius * np.cos(a), radius * np.sin(a)])
    xy[-1] = xy[0]  # closed exactly: the road is a loop
    return LineString(xy)


def test_follow_road_goes_round_a_circle_at_the_speed():
    road = _circle()
    p = np.array([50.0, 0.0])
    v = np.array([0.0, 10.0])  # counter-clockwise, tangent
    times = np.array([0.0, 5.0, 10.0])
    pts = follow_road([road], p, v, times)
    angles = np.arctan2(pts[:, 1], pts[:, 0])
    np.testing.assert_allclose(angles, 10.0 * times / 50.0, atol=2e-3)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 50.0, atol=0.01)
    # driving the other way round, and keeping a lane offset of 1.5 m (outside)
    back = follow_road([road], np.array([50.0, 0.0]), -v, np.array([5.0]))
    assert np.arctan2(back[0, 1], back[0, 0]) == pytest.approx(-1.0, abs=2e-3)
    # the offset from the centreline at the start is kept (as a vector in the plane)
    line = LineString([(0, 0), (100, 0)])
    off = follow_road([line], np.array([10.0, -1.5]), np.array([5.0, 0.0]), np.array([2.0]))
    np.testing.assert_allclose(off[0], [20.0, -1.5], atol=1e-9)


def test_follow_road_gives_up_off_the_road_at_rest_and_without_roads():
    road = LineString([(0, 0), (100, 0)])
    assert follow_road([road], np.array([10.0, 20.0]), np.array([5.0, 0.0]), np.ones(1)) is None
    assert follow_road([road], np.array([10.0, 1.0]), np.array([0.01, 0.0]), np.ones(1)) is None
    assert follow_road([], np.array([10.0, 1.0]), np.array([5.0, 0.0]), np.ones(1)) is None
    # past the end it carries on straight
    pts = follow_road([road], np.array([90.0, 0.0]), np.array([5.0, 0.0]), np.array([4.0]))
    np.testing.assert_allclose(pts[0], [110.0, 0.0], atol=1e-9)


# ------------------------------------------------------------------ reacquirer
def _lost_state(t_s: float = 0.0) -> GaussianState:
    """A car at (0, 0) heading east at 8 m/s, well tracked."""
    p = np.diag([0.3, 0.3, 0.5, 0.5]) ** 2
    return GaussianState(t_s, np.array([0.0, 0.0, 8.0, 0.0]), p, 0.0)


def test_road_following_reacquirer_explains_a_car_round_the_bend():
    # the road runs east 40 m, then north: after 10 s the car is 40 m up the north leg
    road = LineString([(-50, 0), (40, 0), (40, 200)])
    kf = KalmanFilter(ConstantVelocity(3.0), 10.0)
    state = _lost_state()
    rng = np.random.default_rng(0)
    there, cov = np.array([40.0, 40.0]), 0.5 * np.eye(2)
    clutter = 1e-4
    plain = MotionReacquirer().density(kf, state, 0.0, state.x[:2], 10.0, there, cov, rng)
    road_d = RoadFollowingReacquirer([road]).density(
        kf, state, 0.0, state.x[:2], 10.0, there, cov, rng
    )
    assert plain < clutter < road_d
    # a car in the field where the straight line would have put it is not explained better
    straight = np.array([80.0, 0.0])
    on_road = RoadFollowingReacquirer([road]).density(
        kf, state, 0.0, state.x[:2], 10.0, straight, cov, rng
    )
    assert on_road < road_d


def test_road_prediction_keeps_the_along_spread_and_caps_the_across():
    road = LineString([(-50, 0), (500, 0)])
    re = RoadFollowingReacquirer([road], across_sigma_m=2.0)
    cov = np.diag([400.0, 400.0])
    mean, out = re.predict(np.array([0.0, 0.0]), np.array([8.0, 0.0]), 10.0, cov)
    np.testing.assert_allclose(mean, [80.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(out, np.diag([400.0, 4.0]), atol=1e-9)
    assert gaussian_density(np.zeros(2), out) == pytest.approx(1 / (2 * np.pi * 20 * 2))
    assert re.predict(np.array([0.0, 30.0]), np.array([8.0, 0.0]), 10.0, cov) is None


def test_reacquirer_rejects_bad_settings():
    with pytest.raises(TrackingError):
        RoadFollowingReacquirer([LineString([(0, 0), (1, 0)])], p_off_road=1.5)
