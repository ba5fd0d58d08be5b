"""Road particles with an off-road mode (car parks, yards), and a car driving into a lot."""

import numpy as np
import pytest
from shapely import LineString

from demtrack.core.errors import TrackingError
from demtrack.core.tracking import TrackerConfig, run_tracker
from demtrack.core.tracking.protocols import Candidates
from demtrack.core.tracking.roads import RoadGraph, RoadParticleMotion, RoadParticles
from demtrack.core.tracking.types import Fix

ROAD = LineString([(-200, 0), (200, 0)])


def _cands(xy, sigma=0.3):
    z = np.array([[xy[0], xy[1], 0.0]])
    return Candidates(z, np.array([sigma]), np.ones(1), False)


def _motion(**kw):
    return RoadParticleMotion(RoadGraph([ROAD]), 0.5, 1.0, **kw)


def test_particles_far_from_a_road_start_off_it_and_near_ones_on_it():
    rng = np.random.default_rng(0)
    mo = _motion(leave_rate_per_s=0.1)
    far = mo.initial(_cands((0.0, 20.0)), 200, rng)
    assert far.free.all()
    np.testing.assert_allclose(far.xy.mean(axis=0), [0.0, 20.0], atol=0.1)
    near = mo.initial(_cands((0.0, 1.5)), 200, rng)
    assert not near.free.any()
    np.testing.assert_allclose(near.lateral.mean(), 1.5, atol=0.1)


def test_the_strict_model_snaps_everything_onto_the_road():
    rng = np.random.default_rng(1)
    strict = _motion(leave_rate_per_s=0.0, p_free_init=0.0)
    p = strict.initial(_cands((0.0, 20.0)), 100, rng)
    assert not p.free.any() and np.all(np.abs(p.xy[:, 1]) <= 4.0 + 1e-9)
    p = strict.propagate(p, 1.0, rng)
    assert not p.free.any()


def test_free_particles_move_by_constant_velocity_and_leaving_keeps_the_velocity():
    rng = np.random.default_rng(2)
    mo = RoadParticleMotion(RoadGraph([ROAD]), 1e-9, 1.0, leave_rate_per_s=1e9)
    n = 50
    on = RoadParticles(
        np.zeros(n, dtype=np.int64), np.full(n, 100.0), np.full(n, 5.0), np.zeros(n),
        np.zeros((n, 2)),
    )  # fmt: skip
    moved = mo.propagate(on, 0.1, rng)
    # every particle left the road at once, heading along it at its speed (+x, 5 m/s)
    assert moved.free.all()
    np.testing.assert_allclose(moved.vxy, np.tile([5.0, 0.0], (n, 1)), atol=1e-3)
    later = mo.propagate(moved, 2.0, rng)
    np.testing.assert_allclose(later.xy - moved.xy, np.tile([10.0, 0.0], (n, 1)), atol=1e-3)
    kept = mo.take(later, np.array([0, 0, 3]))
    assert kept.free.shape == (3,) and kept.vxy.shape == (3, 2)


def test_free_particles_near_a_road_rejoin_it_with_their_along_road_speed():
    rng = np.random.default_rng(3)
    mo = RoadParticleMotion(RoadGraph([ROAD]), 1e-9, 1.0, leave_rate_per_s=0.0, join_rate_per_s=1e9)
    n = 10
    xy = np.column_stack([np.linspace(-50, 50, n), np.full(n, 2.0)])
    free = RoadParticles(
        np.zeros(n, dtype=np.int64), np.zeros(n), np.zeros(n), np.zeros(n), xy,
        np.ones(n, dtype=bool), np.tile([3.0, 4.0], (n, 1)),
    )  # fmt: skip
    out = mo.propagate(free, 0.1, rng)
    assert not out.free.any()
    np.testing.assert_allclose(np.abs(out.v), 3.0, atol=1e-3)  # the along-road part
    # and one that is far from every road stays free
    far = RoadParticles(
        np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1), np.zeros(1),
        np.array([[0.0, 30.0]]), np.ones(1, dtype=bool), np.array([[1.0, 0.0]]),
    )  # fmt: skip
    assert mo.propagate(far, 0.1, rng).free.all()


def test_road_motion_rejects_bad_rates():
    with pytest.raises(TrackingError):
        _motion(leave_rate_per_s=-1.0)
    with pytest.raises(TrackingError):
        _motion(p_free_init=2.0)


def _lot_run() -> tuple[list[Fix], np.ndarray, np.ndarray]:
    """A car drives east along the road, turns left off it into a lot and drives north.

    5 m/s; the turn is a quarter circle of 8 m radius; one camera, one hit per fix
    (0.5 m 1-sigma), 10 Hz.
    """
    rng = np.random.default_rng(4)
    arc = np.linspace(-np.pi / 2, 0.0, 30)
    path = LineString(
        [(-40.0, 0.0), (-8.0, 0.0)]
        + [(-8.0 + 8.0 * np.cos(a), 8.0 + 8.0 * np.sin(a)) for a in arc]
        + [(0.0, 60.0)]
    )
    t = np.arange(0.0, 18.0, 0.1)
    truth = np.array([path.interpolate(5.0 * tk).coords[0] for tk in t])
    x, y = truth[:, 0], truth[:, 1]
    fixes = []
    for k, tk in enumerate(t):
        p = np.array([x[k], y[k], 0.0])
        hit = p + np.append(rng.normal(0.0, 0.5, 2), 0.0)
        origin = np.array([0.0, -150.0, 20.0])
        fixes.append(Fix(tk, "cam", "vehicle", k, origin, hit - origin, hit[None], [0.5]))
    return fixes, t, truth


@pytest.mark.parametrize("strict", [False, True])
def test_a_car_leaving_the_road_is_followed_only_with_the_off_road_mode(strict):
    fixes, t, truth = _lot_run()
    cfg = TrackerConfig(
        road_leave_rate_per_s=0.0 if strict else 0.1,
        road_free_init=0.0 if strict else 0.05,
        n_particles=300,
    )
    tracks = run_tracker(fixes, "multi-hypothesis-road", roads=[ROAD], config=cfg)
    in_lot = []
    for track in tracks:
        for p in track.points:
            if p.t_s > 12.0:  # 20 m and more into the lot
                k = int(round(p.t_s * 10))
                in_lot.append(float(np.hypot(*(p.p_enu[:2] - truth[k]))))
    if strict:
        # on the road only: nothing follows the car far into the lot
        assert not in_lot or max(in_lot) > 3.0
    else:
        assert len(tracks) == 1 and in_lot and max(in_lot) < 2.0


def test_road_rule_point_becomes_the_centre_and_both_lane_centres_along_the_ray():
    from demtrack.core.tracking.measurement import RoadHit

    # a ray crossing the x-axis road at 30 degrees, hitting the centreline at (10, 0)
    a = np.radians(30.0)
    g = np.array([np.cos(a), np.sin(a)])
    road_pt = np.array([10.0, 0.0, 0.0])
    origin = road_pt - 100.0 * np.append(g, -0.2)
    cov = np.array([np.diag([25.0, 25.0])])  # a vague terrain hit
    fix = Fix(
        0.0, "cam", "vehicle", 0, origin, road_pt - origin, road_pt[None], [5.0],
        road_hit_enu=road_pt, hit_cov_en_m2=cov,
    )  # fmt: skip
    model = RoadHit(0.5, RoadGraph([ROAD]), lane_offset_m=1.5, lane_sigma_m=0.5)
    c = model.candidates(fix)
    assert c.mixture and c.size == 3
    shift = 1.5 / np.sin(a)  # 3 m along the ray to reach y = +-1.5
    np.testing.assert_allclose(
        c.z_enu[:, :2], [road_pt[:2] - shift * g, road_pt[:2], road_pt[:2] + shift * g], atol=1e-9
    )
    np.testing.assert_allclose(np.abs(c.z_enu[:, 1]), [1.5, 0.0, 1.5], atol=1e-9)
    # along the ray 0.5 m + lane_sigma / sin(a) = 1 m more; across it 0.5 m
    along = g @ c.cov(0) @ g
    across = np.array([-g[1], g[0]]) @ c.cov(0) @ np.array([-g[1], g[0]])
    assert along == pytest.approx(0.5**2 + 1.0**2) and across == pytest.approx(0.5**2)
    # without the network: the rule's point alone
    assert RoadHit(0.5).candidates(fix).size == 1
