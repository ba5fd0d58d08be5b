from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CameraError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.visibility.viewshed import (
    PanTiltLimits,
    blind_spot_labels,
    blind_spots,
    viewshed,
)

INTR = Intrinsics(100.0, 100.0, 99.5, 74.5, 200, 150)


def plane(nrows=80, cell=1.0):
    grid = GridSpec(-40.0, 40.0, cell, nrows, nrows)
    return Dem(grid, np.zeros(grid.shape, np.float32))


def wall_dem():
    dem = plane()
    z = np.array(dem.elevation)
    x, y = dem.grid.centres()
    z[(x > 9) & (x < 12) & (np.abs(y) < 15)] = 6.0
    z[(x < -30) & (y > 25)] = np.nan  # a hole: never visible
    return Dem(dem.grid, z)


def brute_force_visible(dem, c, target_height_m, max_range_m):
    """Independent oracle: sample every sight line densely against Dem.sample."""
    x, y = dem.grid.centres()
    tz = dem.elevation + target_height_m
    out = np.zeros(dem.grid.shape, bool)
    margin = np.full(dem.grid.shape, np.inf)
    t = np.linspace(0.0, 1.0, 2001)[:-1]
    for r in range(dem.grid.nrows):
        for k in range(dem.grid.ncols):
            if not np.isfinite(tz[r, k]):
                continue
            p = np.array([x[r, k], y[r, k], tz[r, k]])
            if np.linalg.norm(p - c) > max_range_m:
                continue
            line = c[None, :] + t[:, None] * (p - c)[None, :]
            s = dem.sample(line[:, 0], line[:, 1])
            gap = np.where(np.isfinite(s), line[:, 2] - s, np.inf)
            # Ignore the last stretch where the line reaches its own target cell.
            near = t > 1 - 1e-3 - 0.05 / np.linalg.norm(p - c)
            margin[r, k] = gap[~near].min()
            out[r, k] = margin[r, k] > 0
    return out, margin


def test_flat_plane_reachable_sees_everything_in_range():
    dem = plane()
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 10.0], 0.0, -30.0, 0.0)
    seen = viewshed(dem, cam, mode="reachable", target_height_m=0.0, max_range_m=30.0)
    x, y = dem.grid.centres()
    in_range = np.sqrt(x**2 + y**2 + 100.0) <= 30.0
    np.testing.assert_array_equal(seen, in_range)


def test_wall_shadow_matches_a_brute_force_sight_line_oracle():
    dem = wall_dem()
    c = np.array([0.0, 0.0, 10.0])
    cam = Camera.from_azimuth_tilt_roll(INTR, c, 90.0, -20.0, 0.0)
    seen = viewshed(dem, cam, mode="reachable", target_height_m=0.5, max_range_m=60.0)
    ref, margin = brute_force_visible(dem, c, 0.5, 60.0)
    disagree = seen != ref
    # Only lines that graze within a few centimetres may differ (tolerance, sampling).
    assert np.all(np.abs(margin[disagree]) < 0.06)
    assert ref.sum() > 1000 and (~ref & np.isfinite(dem.elevation)).sum() > 100  # a real shadow
    assert not seen[~np.isfinite(dem.elevation)].any()


def test_fov_mode_keeps_only_cells_in_the_image():
    dem = plane()
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, -35.0, 10.0], 0.0, -25.0, 0.0)
    seen = viewshed(dem, cam, mode="fov", target_height_m=0.0, max_range_m=500.0)
    x, y = dem.grid.centres()
    pts = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    u, v, front = cam.project(pts)
    in_img = front & cam.in_image(np.nan_to_num(u, nan=-1e9), np.nan_to_num(v, nan=-1e9))
    np.testing.assert_array_equal(seen.ravel(), in_img)
    assert 200 < seen.sum() < 0.8 * seen.size


def test_pan_limits_cut_a_sector():
    dem = plane()
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 10.0], 0.0, -30.0, 0.0)
    half_x = np.degrees(np.arctan(100.0 / 100.0))  # 45 deg half-FOV
    limits = PanTiltLimits(pan_min_deg=-10.0, pan_max_deg=10.0)
    seen = viewshed(
        dem,
        cam,
        mode="reachable",
        mount_yaw_deg=90.0,
        limits=limits,
        target_height_m=0.0,
        max_range_m=100.0,
    )
    x, y = dem.grid.centres()
    az = np.degrees(np.arctan2(x, y))
    inside = np.abs(az - 90.0) < 10.0 + half_x - 0.5
    outside = np.abs(((az - 90.0 + 180) % 360) - 180) > 10.0 + half_x + 0.5
    assert seen[inside & (np.hypot(x, y) > 1)].all()
    assert not seen[outside].any()


def test_curvature_lowers_distant_targets():
    dem = plane(nrows=40, cell=100.0)  # 4 km square
    z = np.zeros(dem.grid.shape, np.float32)
    z[:, 24] = 0.8  # a low bank 500 m east of the camera
    dem = Dem(dem.grid, z)
    cam = Camera.from_azimuth_tilt_roll(INTR, [50.0, 50.0, 2.0], 90.0, 0.0, 0.0)
    flat = viewshed(dem, cam, mode="reachable", target_height_m=1.0, max_range_m=5000.0)
    curved = viewshed(
        dem, cam, mode="reachable", target_height_m=1.0, max_range_m=5000.0, curvature=True
    )
    assert curved.sum() < flat.sum()


def test_bad_mode_and_range():
    dem = plane()
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 10.0], 0.0, -30.0, 0.0)
    with pytest.raises(CameraError, match="unknown viewshed mode 'x'"):
        viewshed(dem, cam, mode="x")
    with pytest.raises(CameraError, match="max_range_m must be positive"):
        viewshed(dem, cam, max_range_m=0.0)


def test_blind_spots_are_connected_areas_largest_first():
    dem = plane(nrows=20)
    count = np.ones(dem.grid.shape, int)
    count[2:6, 2:5] = 0  # 12 cells
    count[10:12, 15:17] = 0  # 4 cells
    spots = blind_spots(count, dem)
    assert [s.area_m2 for s in spots] == [12.0, 4.0]
    x, y = dem.grid.centres()
    assert spots[0].centroid_e_m == pytest.approx(x[2:6, 2:5].mean())
    assert spots[0].centroid_n_m == pytest.approx(y[2:6, 2:5].mean())
    assert spots[0].bbox == pytest.approx((-38.0, 34.0, -35.0, 38.0))  # cell edges
    labels = blind_spot_labels(count, dem)  # each spot's cells, by its label
    assert (labels == spots[0].label)[2:6, 2:5].all() and (labels == spots[0].label).sum() == 12
    assert (labels == spots[1].label)[10:12, 15:17].all() and (labels == spots[1].label).sum() == 4
    assert (labels > 0).sum() == 16
    assert len(blind_spots(count, dem, min_area_m2=5.0)) == 1


def test_target_behind_a_wall_is_partly_then_fully_visible_as_it_grows():
    from demtrack.core.visibility.viewshed import target_visible_fraction

    dem = plane()
    z = np.array(dem.elevation)
    x, y = dem.grid.centres()
    z[(x > 9) & (x < 12)] = 2.0  # a 2 m wall across the view
    dem = Dem(dem.grid, z)
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 3.0], 90.0, -5.0, 0.0)
    foot = np.array([[30.0, 0.0, 0.0]])
    # The sight line over the wall top (x ~ 10.5..11, z = 2) from z = 3 reaches
    # z = 3 - (3 - 2) * 30 / d_wall at x = 30; heights above that are seen.
    d_wall = 10.75
    z_min = 3.0 - 1.0 * 30.0 / d_wall
    f_short = target_visible_fraction(dem, cam, foot, 0.2)[0]
    f_tall = target_visible_fraction(dem, cam, foot, 4.0)[0]
    assert f_short == 0.0
    levels = np.linspace(0.05, 1.0, 8) * 4.0
    assert f_tall == pytest.approx(np.mean(levels > z_min), abs=1 / 8)
    open_ground = target_visible_fraction(dem, cam, np.array([[5.0, 0.0, 0.0]]), 1.7)[0]
    assert open_ground == 1.0
    behind_camera = target_visible_fraction(dem, cam, np.array([[-20.0, 0.0, 0.0]]), 1.7)[0]
    assert behind_camera == 0.0
