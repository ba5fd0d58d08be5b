"""Bulk geolocation: one batch across sensors gives exactly the per-pixel answers."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import shapely

from demtrack.core.geolocation import fix_builder as fix_builder_mod
from demtrack.core.geolocation import geolocate as geolocate_mod
from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.geolocation.geolocate import RULES
from demtrack.core.geolocation.roads import RoadNetwork
from demtrack.core.geolocation.uncertainty import hit_covariance, hit_covariances
from demtrack.core.raycast import cast as raycast_mod
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def _random_views(site, n_per_sensor: int, seed: int = 0) -> list[tuple]:
    """Random pixels of every sensor, weighted to the lower image (where the ground is)."""
    rng = np.random.default_rng(seed)
    views = []
    for sid in sorted(site.sensors):
        cam = site.sensors[sid].camera
        w, h = cam.intrinsics.width, cam.intrinsics.height
        u = rng.uniform(-0.5, w - 0.5, n_per_sensor)
        k = n_per_sensor // 4
        v = np.concatenate(
            [rng.uniform(-0.5, h - 0.5, k), rng.uniform(h / 3, h - 0.5, n_per_sensor - k)]
        )
        views.append((cam, u, v))
    return views


def _same_hit(a, b) -> None:
    # Camera.pixel_to_ray rotates a batch of pixels with one matrix product, whose last
    # bit may differ from one pixel's: the rays, hence everything after, agree to rounding.
    assert a.source == b.source
    np.testing.assert_allclose(a.p_enu, b.p_enu, rtol=0, atol=1e-9)
    np.testing.assert_allclose([a.lat_deg, a.lon_deg], [b.lat_deg, b.lon_deg], rtol=0, atol=1e-13)
    assert a.h_m == pytest.approx(b.h_m, abs=1e-9)
    assert a.range_m == pytest.approx(b.range_m, abs=1e-9)
    assert a.sigma_m == pytest.approx(b.sigma_m, rel=1e-9)
    np.testing.assert_allclose(a.cov_en_m2, b.cov_en_m2, rtol=1e-9, atol=1e-15)


def _same_location(a, b) -> None:
    assert (a.u, a.v, a.status, a.rule, a.crossed_nodata) == (
        b.u,
        b.v,
        b.status,
        b.rule,
        b.crossed_nodata,
    )
    np.testing.assert_array_equal(a.origin_enu, b.origin_enu)
    np.testing.assert_allclose(a.direction_enu, b.direction_enu, rtol=0, atol=1e-15)
    assert len(a.hits) == len(b.hits) and len(a.selected) == len(b.selected)
    for x, y in zip(a.hits + a.selected, b.hits + b.selected, strict=True):
        _same_hit(x, y)
    assert (a.road is None) == (b.road is None)
    if a.road is not None:
        _same_hit(a.road, b.road)


def test_batch_of_rays_is_bit_identical_to_ray_by_ray(site):
    geo = site.geolocator()
    rays = []
    for cam, u, v in _random_views(site, 80, seed=5):
        for k in range(len(u)):  # each ray exactly as a one-pixel request makes it
            o, d = cam.pixel_to_ray([u[k]], [v[k]])
            axes, sig = geolocate_mod._pixel_perturbations(cam, u[k : k + 1], v[k : k + 1], 1.0)
            rays.append((o, d, axes, sig))
    o, d, axes, sig = (np.concatenate(parts) for parts in zip(*rays, strict=True))
    batch = geo.locate_rays(o, d, axes, sig)
    assert batch.has_road.sum() > 5 and (batch.counts > 1).sum() > 5
    for i in range(len(o)):
        one = geo.locate_rays(o[i : i + 1], d[i : i + 1], axes[i : i + 1], sig[i : i + 1])
        lo, hi = batch.offsets[i], batch.offsets[i + 1]
        assert one.status[0] == batch.status[i] and one.counts[0] == hi - lo
        assert one.crossed_nodata[0] == batch.crossed_nodata[i]
        for name in ("points_enu", "range_m", "sigma_m", "cov_en_m2"):
            np.testing.assert_array_equal(getattr(one, name), getattr(batch, name)[lo:hi])
        for name in ("road_enu", "road_range_m", "road_sigma_m", "road_cov_en_m2"):
            np.testing.assert_array_equal(getattr(one, name)[0], getattr(batch, name)[i])


@pytest.mark.parametrize("rule", RULES)
def test_one_batch_across_sensors_equals_pixel_by_pixel(site, rule):
    geo = site.geolocator()
    views = _random_views(site, 60)
    batch = geo.geolocate_many(views, rule)
    assert [len(locs) for locs in batch] == [len(u) for _, u, _ in views]
    statuses = set()
    n_road = n_multi = 0
    for (cam, u, v), locs in zip(views, batch, strict=True):
        for k, loc in enumerate(locs):
            (single,) = geo.geolocate(cam, [u[k]], [v[k]], rule=rule)
            _same_location(loc, single)
            statuses.add(loc.status)
            n_road += loc.road is not None
            n_multi += len(loc.hits) > 1
    # The sample covers the cases that matter: hits, road points, several crossings.
    assert "hit" in statuses and n_road > 0 and n_multi > 0
    if rule == "road":
        assert "no_road" in statuses


def test_per_camera_geolocate_equals_its_part_of_the_batch(site):
    geo = site.geolocator()
    views = _random_views(site, 40, seed=1)
    batch = geo.geolocate_many(views, "all")
    for (cam, u, v), locs in zip(views, batch, strict=True):
        for a, b in zip(geo.geolocate(cam, u, v, rule="all"), locs, strict=True):
            _same_location(a, b)


def test_bulk_road_rule_equals_the_scalar_rule(site):
    rng = np.random.default_rng(2)
    roads, dem = site.roads, site.dem
    cams = [s.camera for s in site.sensors.values()]
    origins = np.vstack([np.repeat(c.position_enu[None], 150, axis=0) for c in cams])
    dirs = rng.normal(size=(len(origins), 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) * rng.uniform(0.02, 0.5, len(dirs))
    dirs[:5] = [0.0, 0.0, -1.0]  # straight down: no ground track
    got = roads.best_candidates(origins, dirs, dem, 1000.0, 3.0)
    assert got.found.sum() > 20 and (~got.found).sum() > 20
    for i in range(len(origins)):
        want = roads.best_candidate(origins[i], dirs[i], dem, 1000.0, 3.0)
        assert got.found[i] == (want is not None)
        if want is not None:
            np.testing.assert_allclose(got.p_enu[i], want.p_enu, rtol=0, atol=1e-9)
            assert got.vertical_gap_m[i] == pytest.approx(want.vertical_gap_m, abs=1e-9)
            assert got.road_index[i] == want.road_index
        else:
            assert np.isnan(got.p_enu[i]).all() and got.road_index[i] == -1


def test_bulk_road_rule_on_crossing_roads_and_an_empty_network(site):
    dem = site.dem
    x0, y0 = dem.grid.x_min + 100.0, dem.grid.y_max - 100.0
    # Two roads crossing in a plus; the ray's track crosses both.
    net = RoadNetwork(
        (
            shapely.LineString([(x0, y0 - 50), (x0, y0 + 50)]),
            shapely.LineString([(x0 - 50, y0), (x0 + 50, y0)]),
        )
    )
    z = float(dem.sample(np.array([x0]), np.array([y0]))[0])
    o = np.array([[x0 - 40.0, y0 - 30.0, z + 50.0]])
    d = np.array([[40.0, 30.0, -50.0]])  # through the junction exactly
    got = net.best_candidates(o, d, dem, 1000.0, 1e-6)
    want = net.best_candidate(o[0], d[0], dem, 1000.0, 1e-6)
    assert want is not None and got.found[0]
    np.testing.assert_allclose(got.p_enu[0], want.p_enu, atol=1e-9)
    empty = RoadNetwork(())
    assert not empty.best_candidates(o, d, dem, 1000.0).found.any()
    assert net.best_candidates(np.zeros((0, 3)), np.zeros((0, 3)), dem, 10.0).found.shape == (0,)


def test_batched_covariances_equal_the_per_ray_model():
    rng = np.random.default_rng(3)
    m = 200
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d[:, 2] = -np.abs(d[:, 2])
    lam = rng.uniform(1, 900, m)
    grad = rng.normal(scale=0.3, size=(m, 2))
    axes = rng.normal(size=(m, 2, 3))
    sig = rng.uniform(1e-4, 2e-3, (m, 2))
    sz = rng.uniform(0, 0.5, m)
    got = hit_covariances(d, lam, grad, axes, sig, sz)
    for k in range(m):
        want = hit_covariance(d[k], lam[k : k + 1], grad[k : k + 1], axes[k], sig[k], sz[k : k + 1])
        np.testing.assert_allclose(got[k], want[0], rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert hit_covariances(d[:0], lam[:0], grad[:0], axes[:0], sig[:0], sz[:0]).shape == (0, 2, 2)


def test_serial_and_threaded_casts_agree_and_the_thread_setting_is_restored(site, monkeypatch):
    geo = site.geolocator()
    views = _random_views(site, 30, seed=4)
    threads = numba.get_num_threads()
    serial = geo.locate_pixels(views)
    assert numba.get_num_threads() == threads
    monkeypatch.setattr(raycast_mod, "SERIAL_CAST_MAX_RAYS", 0)
    threaded = geo.locate_pixels(views)
    for name in ("status", "offsets", "points_enu", "range_m", "cov_en_m2", "road_enu"):
        np.testing.assert_array_equal(getattr(serial, name), getattr(threaded, name))


def test_fixes_of_a_batch_equal_fixes_one_detection_at_a_time(site):
    dets = list(make_scenario(site, "passing-vehicles").detections[:150])
    dets += list(make_scenario(site, "pedestrians").detections[:100])
    dets.sort(key=lambda d: d.t_s)
    fixes, report = build_fixes(site, dets)
    assert report.n_fixes == len(fixes) > 200
    singles = {}
    for i, d in enumerate(dets):
        got, _ = build_fixes(site, [d])
        if got:
            singles[i] = got[0]
    assert sorted(singles) == [f.detection_index for f in fixes]
    for f in fixes:
        s = singles[f.detection_index]
        assert (f.t_s, f.sensor, f.cls, f.score) == (s.t_s, s.sensor, s.cls, s.score)
        assert f.n_hits == s.n_hits
        for name in ("origin_enu", "direction_enu", "hits_enu"):
            np.testing.assert_allclose(getattr(f, name), getattr(s, name), rtol=0, atol=1e-9)
        np.testing.assert_allclose(f.hit_sigma_m, s.hit_sigma_m, rtol=1e-9)
        np.testing.assert_allclose(f.hit_cov_en_m2, s.hit_cov_en_m2, rtol=1e-9, atol=1e-15)
        assert (f.road_hit_enu is None) == (s.road_hit_enu is None)
        if f.road_hit_enu is not None:
            np.testing.assert_allclose(f.road_hit_enu, s.road_hit_enu, rtol=0, atol=1e-9)


def test_bulk_road_rule_with_a_track_along_a_road_and_through_a_vertex(site):
    """Collinear ground tracks (overlap) and crossings at a vertex, as the scalar rule."""
    dem = site.dem
    x0, y0 = dem.grid.x_min + 100.0, dem.grid.y_max - 100.0
    net = RoadNetwork(
        (
            shapely.LineString([(x0, y0), (x0 + 60, y0), (x0 + 60, y0 + 40)]),
            shapely.LineString([(x0 - 20, y0 - 30), (x0 + 10, y0 + 30)]),
        )
    )
    z = float(dem.sample(np.array([x0]), np.array([y0]))[0])
    o = np.array(
        [
            [x0 - 30.0, y0, z + 20.0],  # along the first road's first segment
            [x0 + 40.0, y0 - 20.0, z + 30.0],  # through the vertex (x0 + 60, y0)
            [x0 - 50.0, y0 + 10.0, z + 25.0],  # across both roads
        ]
    )
    d = np.array([[1.0, 0.0, -0.1], [20.0, 20.0, -3.0], [1.0, -0.05, -0.05]])
    got = net.best_candidates(o, d, dem, 200.0)
    for i in range(len(o)):
        want = net.best_candidate(o[i], d[i], dem, 200.0)
        assert want is not None and got.found[i]
        np.testing.assert_allclose(got.p_enu[i], want.p_enu, rtol=0, atol=1e-9)
        assert got.road_index[i] == want.road_index


def test_rays_and_perturbations_in_one_pass_equal_the_camera_and_the_reference(site):
    """The fused helper gives pixel_to_ray's rays and _pixel_perturbations' bits."""
    for cam, u, v in _random_views(site, 200, seed=11):
        w, h = cam.intrinsics.width, cam.intrinsics.height
        u = np.concatenate([u, [-0.5, w - 0.5, -0.5, w - 0.5, (w - 1) / 2]])
        v = np.concatenate([v, [-0.5, -0.5, h - 0.5, h - 0.5, (h - 1) / 2]])
        o, d, axes, sig = geolocate_mod._rays_and_perturbations(cam, u, v, 1.5)
        o_ref, d_ref = cam.pixel_to_ray(u, v)
        axes_ref, sig_ref = geolocate_mod._pixel_perturbations(cam, u, v, 1.5)
        for got, want in ((o, o_ref), (d, d_ref), (axes, axes_ref), (sig, sig_ref)):
            assert got.shape == want.shape
            np.testing.assert_array_equal(got, want)


class _WrappedCamera:
    """A camera that is not a Camera: locate_pixels takes its general path."""

    def __init__(self, cam) -> None:
        self._cam = cam
        self.intrinsics = cam.intrinsics
        self.R_world_cam = cam.R_world_cam

    def pixel_to_ray(self, u, v):
        return self._cam.pixel_to_ray(u, v)


def test_locate_pixels_fast_path_equals_the_general_path(site):
    geo = site.geolocator()
    views = _random_views(site, 60, seed=12)
    fast = geo.locate_pixels(views)
    general = geo.locate_pixels([(_WrappedCamera(c), u, v) for c, u, v in views])
    one = geo.locate_pixels(views[:1])
    one_general = geo.locate_pixels([(_WrappedCamera(c), u, v) for c, u, v in views[:1]])
    for name in vars(fast):
        np.testing.assert_array_equal(getattr(fast, name), getattr(general, name))
        np.testing.assert_array_equal(getattr(one, name), getattr(one_general, name))


def test_centre_shift_without_masks_equals_the_masked_arithmetic():
    rng = np.random.default_rng(3)
    n = 40
    ground = rng.normal(size=(n, 3))
    ground[:, 2] = 0.0
    norm = np.linalg.norm(ground, axis=1)
    ray = np.repeat(np.arange(n), rng.integers(0, 3, n))
    a = rng.normal(size=(len(ray), 2, 2))
    cov = a @ np.swapaxes(a, 1, 2)
    offset, var_along, var_across = (rng.uniform(0.1, 2.0, n) for _ in range(3))
    args = (ground, norm, offset, ray, cov, var_along, var_across)
    fast = fix_builder_mod._centre_shift(*args)
    masked = fix_builder_mod._centre_shift(*args, masked=True)
    for got, want in zip(fast, masked, strict=True):
        np.testing.assert_array_equal(got, want)
    # A straight-down ray takes the masked path: no shift, no along part.
    ground[0, :2] = 0.0
    norm[0] = 0.0
    shift, cov_out = fix_builder_mod._centre_shift(*args)
    np.testing.assert_array_equal(shift[0], 0.0)
    np.testing.assert_array_equal(shift[1:], masked[0][1:])
    hits0 = ray == 0
    np.testing.assert_array_equal(cov_out[hits0], cov[hits0] + var_across[0] * np.eye(2))


def test_bulk_road_rule_for_rays_from_off_the_dem_equals_the_scalar_rule(site):
    """Ground tracks clipped to the DEM: rays entering it from outside, leaving it, or
    passing it by give the scalar rule's answer (it intersects the whole track)."""
    rng = np.random.default_rng(7)
    roads, dem = site.roads, site.dem
    x0, y0, x1, y1 = dem.grid.centre_bounds
    n = 400
    # origins on a ring 50-400 m outside the DEM, aimed at random points around it
    ang = rng.uniform(0, 2 * np.pi, n)
    rad = 0.5 * max(x1 - x0, y1 - y0) + rng.uniform(50, 400, n)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    o = np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang), rng.uniform(30, 120, n)])
    aim = np.column_stack(
        [rng.uniform(x0 - 100, x1 + 100, n), rng.uniform(y0 - 100, y1 + 100, n), np.zeros(n)]
    )
    aim[:, 2] = np.nan_to_num(dem.sample(aim[:, 0], aim[:, 1]), nan=float(np.nanmin(dem.elevation)))
    d = aim - o
    d[:10, :2] = 0.0  # straight down, off the DEM
    d[10:20] = np.column_stack(
        [-(o[10:20, :2] - [cx, cy]), np.full(10, -1.0)]
    )  # through the middle
    d[20:30, 2] = 0.0  # level
    got = roads.best_candidates(o, d, dem, 2000.0, 3.0)
    assert got.found.sum() > 20 and (~got.found).sum() > 20
    for i in range(n):
        want = roads.best_candidate(o[i], d[i], dem, 2000.0, 3.0)
        assert got.found[i] == (want is not None), i
        if want is not None:
            np.testing.assert_allclose(got.p_enu[i], want.p_enu, rtol=0, atol=1e-9)
            assert got.vertical_gap_m[i] == pytest.approx(want.vertical_gap_m, abs=1e-9)
            assert got.road_index[i] == want.road_index
