from __future__ import annotations

import json

import numpy as np
import pytest

from demtrack.core.site.folder import load_site
from demtrack.core.site.orthophoto import read_orthophoto
from demtrack.core.terrain.dem import Dem
from demtrack.samplesite.cameras import sighting_heads
from demtrack.samplesite.scan import coarse_dem, simulate_laser_scan
from demtrack.samplesite.world import make_world


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def test_dem_cells_are_the_mean_variance_and_count_of_their_laser_points(site, sample_site_dir):
    pts = np.load(sample_site_dir / "laser_points.npy").astype(np.float64)
    dem = site.dem
    rows, cols = dem.grid.cell_of(pts[:, 0], pts[:, 1])
    rng = np.random.default_rng(0)
    hit = np.flatnonzero(dem.count.ravel() > 0)
    for flat in rng.choice(hit, 40, replace=False):
        r, c = divmod(int(flat), dem.grid.ncols)
        z = pts[(rows == r) & (cols == c), 2]
        assert dem.count[r, c] == len(z)
        assert dem.elevation[r, c] == pytest.approx(z.mean(), abs=1e-4)
        assert dem.variance[r, c] == pytest.approx(z.var(), abs=1e-4)


def test_holes_are_filled_from_the_coarse_dem_and_the_field_centre_is_a_hole(site, sample_site_dir):
    dem = site.dem
    coarse = Dem.read(sample_site_dir / "coarse_dem_30m.tif")
    assert not dem.nodata.any()
    x, y = dem.grid.centres()
    f = dem.filled
    np.testing.assert_allclose(dem.elevation[f], coarse.sample(x[f], y[f]), atol=1e-4)
    # The helicopter flew the roads: the middle of the field got no points.
    r, c = dem.grid.cell_of(np.array([-8.0]), np.array([12.0]))
    assert dem.filled[r[0], c[0]] and dem.count[r[0], c[0]] == 0
    assert 0.3 < dem.coverage < 0.8


def test_dem_matches_the_true_surface_where_the_laser_saw_open_ground(site):
    world = make_world()
    dem = site.dem
    x, y = dem.grid.centres()
    open_ground = (dem.count >= 3) & ~np.isfinite(world.crown_z(x, y))
    open_ground &= ~np.isfinite(world.building_z(x, y))
    err = dem.elevation[open_ground] - world.ground_z(x[open_ground], y[open_ground])
    # 5 cm range noise averaged over the cell; a few cells catch a crown or roof edge.
    assert np.median(np.abs(err)) < 0.05
    assert np.mean(np.abs(err) < 0.25) > 0.99


def test_yaw_calibration_recovers_the_true_yaw_and_flags_the_blunder(site, sample_site_dir):
    truth = json.loads((sample_site_dir / "truth.json").read_text())["sensors"]
    for sid, t in truth.items():
        assert abs(t["yaw_error_deg"]) < 0.05
        assert site.sensor(sid).head.mount_yaw_deg == pytest.approx(t["calibrated_mount_yaw_deg"])
    assert truth["cam2"]["outliers"] == ["lot NE corner"]


def test_true_ground_point_projected_into_a_camera_geolocates_back(site):
    world = make_world()
    geo = site.geolocator()
    for spec, head, pan, tilt in sighting_heads(world):
        true_cam = head.camera_at(pan, tilt)
        sensor = site.sensor(spec.id)
        # A point on open ground in front of the camera: the image centre's ground point.
        (g,) = geo.geolocate(
            true_cam, [true_cam.intrinsics.cx], [true_cam.intrinsics.height * 0.75], rule="last"
        )
        p = g.best.p_enu
        p[2] = float(world.ground_z(p[0], p[1]))
        u, v, front = true_cam.project(p[None, :])
        assert front[0]
        (back,) = geo.geolocate(sensor.camera, u, v, rule="last")
        # Residual: calibration error (< 0.05 deg) times range, plus the DEM's height error
        # (<= 0.1 m on open ground) stretched by the grazing angle.
        d = back.direction_enu
        tan_depression = -d[2] / np.hypot(d[0], d[1])
        tol = 0.1 / tan_depression + back.best.range_m * np.radians(0.05)
        assert np.hypot(*(back.best.p_enu[:2] - p[:2])) < tol


def test_orthophoto_and_images_are_coregistered_with_the_site(site, sample_site_dir):
    rgb, grid = read_orthophoto(site.orthophoto_path)
    assert grid.cell_m == 0.25 and grid.bounds == site.dem.grid.bounds
    # Road pixels are asphalt grey or centre-line paint: low saturation.
    line = np.asarray(site.roads.lines[0].coords)
    rows, cols = grid.cell_of(line[:, 0], line[:, 1] + 1.5)
    px = rgb[rows, cols].astype(int)
    assert (px.max(axis=1) - px.min(axis=1) < 30).mean() > 0.95
    from PIL import Image

    for sensor in site.sensors.values():
        img = Image.open(sensor.image_path)
        assert img.size == (sensor.camera.intrinsics.width, sensor.camera.intrinsics.height)


def test_laser_scan_and_coarse_dem_are_deterministic():
    world = make_world()
    a, b = simulate_laser_scan(world, seed=3), simulate_laser_scan(world, seed=3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(coarse_dem(world).elevation, coarse_dem(world).elevation)
