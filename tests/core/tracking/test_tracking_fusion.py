"""Ray triangulation and the pairing of simultaneous fixes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.tracking.config import TrackerConfig
from demtrack.core.tracking.fusion import closest_approach, fuse_measurements, triangulate_fixes
from demtrack.core.tracking.protocols import Measurement
from demtrack.core.tracking.types import Fix

coord = st.floats(-200, 200, allow_nan=False)


@given(
    st.tuples(coord, coord, st.floats(-5, 5)),
    st.tuples(coord, coord, st.floats(10, 60)),
    st.tuples(coord, coord, st.floats(10, 60)),
)
@settings(max_examples=100, deadline=None)
def test_two_exact_rays_recover_the_point(p, oa, ob):
    p, oa, ob = (np.array(v, dtype=float) for v in (p, oa, ob))
    da, db = p - oa, p - ob
    sin = np.linalg.norm(np.cross(da, db)) / (np.linalg.norm(da) * np.linalg.norm(db))
    if sin < 0.05:
        return  # nearly parallel rays: no well-posed answer to 1e-9
    ra = closest_approach(oa, da, ob, db)
    assert ra is not None
    np.testing.assert_allclose(ra.p_enu, p, atol=1e-9)
    assert ra.miss_m < 1e-9
    assert ra.range_a_m == pytest.approx(np.linalg.norm(da))
    assert ra.range_b_m == pytest.approx(np.linalg.norm(db))


def test_skew_rays_give_the_midpoint_of_the_common_perpendicular():
    # x axis at z=0 and a line parallel to y through (3, 0, 2): perpendicular is z
    ra = closest_approach([-5, 0, 0], [1, 0, 0], [3, -4, 2], [0, 2, 0])
    np.testing.assert_allclose(ra.p_enu, [3, 0, 1], atol=1e-12)
    assert ra.miss_m == pytest.approx(2.0)
    assert ra.angle_rad == pytest.approx(math.pi / 2)
    assert ra.range_a_m == pytest.approx(8.0) and ra.range_b_m == pytest.approx(4.0)
    assert closest_approach([0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]) is None


def _ray_fix(origin, target, sensor, t=0.0, cls="vehicle", hits=None, sigma=0.5, road=False):
    origin, target = np.asarray(origin, float), np.asarray(target, float)
    hits = [target] if hits is None else hits
    return Fix(
        t,
        sensor,
        cls,
        0,
        origin,
        target - origin,
        hits,
        [sigma] * len(hits),
        road_hit_enu=target if road else None,
    )


def test_triangulated_fix_checks_geometry_and_terrain():
    cfg = TrackerConfig()
    p = np.array([0.0, -50.0, 0.0])
    a = _ray_fix([-40, 0, 30], p, "west", road=True)
    b = _ray_fix([40, 0, 30], p, "east", t=0.01)
    tri = triangulate_fixes(a, b, cfg)
    np.testing.assert_allclose(tri.hits_enu[0], p, atol=1e-9)
    assert tri.sensor == "east+west" and tri.t_s == pytest.approx(0.005)
    np.testing.assert_allclose(tri.road_hit_enu, p, atol=1e-9)
    # sigma: ray_sigma * range / sin(angle), both ranges ~70.7 m
    angle = math.acos(
        np.dot((p - a.origin_enu), (p - b.origin_enu))
        / np.linalg.norm(p - a.origin_enu)
        / np.linalg.norm(p - b.origin_enu)
    )
    worst = cfg.ray_sigma_rad * np.linalg.norm(p - a.origin_enu) / math.sin(angle)
    # covariance: each ray pins the point across its ground track to the larger of
    # ray_sigma * range (3-D range: the ray's angular error) and its fix's own across-ray
    # sigma (0.5 m here: the object's extent), plus a weak isotropic prior of the old
    # worst-direction sigma and the 5 cm floor
    info = np.eye(2) / worst**2
    for f in (a, b):
        g = (p - f.origin_enu)[:2]
        n = np.array([-g[1], g[0]]) / np.linalg.norm(g)
        s = max(cfg.ray_sigma_rad * np.linalg.norm(p - f.origin_enu), 0.5)
        info += np.outer(n, n) / s**2
    expect = np.linalg.inv(info) + 0.05**2 * np.eye(2)
    np.testing.assert_allclose(tri.hit_cov_en_m2[0], expect, rtol=1e-6)
    assert tri.hit_sigma_m[0] == pytest.approx(math.sqrt(np.linalg.eigvalsh(expect)[-1]))
    # the object's extent (the fixes' 0.5 m) widens it; a point-like object's does not
    tiny = triangulate_fixes(
        _ray_fix([-40, 0, 30], p, "west", sigma=0.01),
        _ray_fix([40, 0, 30], p, "east", sigma=0.01),
        cfg,
    )
    assert np.all(np.linalg.eigvalsh(tri.hit_cov_en_m2[0] - tiny.hit_cov_en_m2[0]) > 0)
    # same sensor, other class, near-parallel rays, rays that miss, off-terrain crossing
    assert triangulate_fixes(a, _ray_fix([40, 0, 30], p, "west"), cfg) is None
    assert triangulate_fixes(a, _ray_fix([40, 0, 30], p, "east", cls="human"), cfg) is None
    assert triangulate_fixes(a, _ray_fix([-40.5, 1, 30], p, "east"), cfg) is None
    assert triangulate_fixes(a, _ray_fix([40, 0, 30], p + [0, 0, 3], "east"), cfg) is None
    far_hits = [p + [0, 25, 0]]
    assert triangulate_fixes(a, _ray_fix([40, 0, 30], p, "east", hits=far_hits), cfg) is None


def test_two_targets_two_sensors_pair_without_ghosts():
    cfg = TrackerConfig()
    p1, p2 = np.array([-10.0, -40.0, 0.0]), np.array([12.0, -35.0, 0.0])
    ow, oe = [-40, 0, 30], [40, 0, 30]
    meas = [
        Measurement(_ray_fix(ow, p1, "west"), (0,), ("west",)),
        Measurement(_ray_fix(ow, p2, "west"), (1,), ("west",)),
        Measurement(_ray_fix(oe, p2, "east"), (2,), ("east",)),
        Measurement(_ray_fix(oe, p1, "east"), (3,), ("east",)),
        Measurement(_ray_fix(oe, [60, -60, 0], "east"), (4,), ("east",)),
    ]
    out = fuse_measurements(meas, cfg)
    assert len(out) == 3
    fused = {frozenset(m.indices): m.fix.hits_enu[0] for m in out if len(m.indices) == 2}
    np.testing.assert_allclose(fused[frozenset((0, 3))], p1, atol=1e-9)
    np.testing.assert_allclose(fused[frozenset((1, 2))], p2, atol=1e-9)
    assert out[-1].indices == (4,) and out[-1].sensors == ("east",)


def test_fixes_too_far_apart_in_time_are_not_fused():
    cfg = TrackerConfig(step_window_s=0.02)
    p = np.array([0.0, -50.0, 0.0])
    meas = [
        Measurement(_ray_fix([-40, 0, 30], p, "west"), (0,), ("west",)),
        Measurement(_ray_fix([40, 0, 30], p, "east", t=0.05), (1,), ("east",)),
    ]
    assert [m.indices for m in fuse_measurements(meas, cfg)] == [(0,), (1,)]
