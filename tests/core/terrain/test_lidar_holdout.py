"""Terrain model from a lidar tile: 10 % of the ground points held out, RMSE at 1 m.

The real, sparse tile (laspy's Autzen sample, fetched at test time) is in
``test_autzen_tile.py``; this one is dense and synthetic, with known truth: a UTM 17N
LAZ written through laspy, smooth terrain (slopes to ~0.15), 3 cm sensor noise on every
return, ASPRS classes 2 (ground), 5 (trees: first returns in the crown, some last
returns reaching the ground) and 6 (buildings: roofs, no ground beneath). It goes through
the real reader, the class selection, the exact UTM -> site-frame conversion and the
per-cell gridding; the held-out points are compared with the bilinear DEM surface.
"""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.terrain.crs_import import points_to_local
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.pointcloud import GROUND_CLASS, read_point_cloud

ANCHOR = (40.3573, -79.6208, 300.0)
NOISE_M = 0.03


def ground(x, y, x0, y0):
    """Ellipsoidal height (m) of the bare earth over UTM coordinates."""
    dx, dy = x - x0, y - y0
    return 300.0 + 0.08 * dx - 0.05 * dy + 2.0 * np.sin(dx / 40.0) * np.cos(dy / 55.0)


@pytest.fixture
def tile(tmp_path, write_las):
    rng = np.random.default_rng(0)
    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(
        ANCHOR[1], ANCHOR[0]
    )
    side, density = 120.0, 6.0  # m, points per m^2
    k = int(side * side * density)
    x = x0 + rng.uniform(-side / 2, side / 2, k)
    y = y0 + rng.uniform(-side / 2, side / 2, k)
    z = ground(x, y, x0, y0) + rng.normal(0.0, NOISE_M, k)
    cls = np.full(k, GROUND_CLASS, np.uint8)
    ret = np.ones(k, np.uint8)
    # A building 20 x 15 m: roof returns only.
    bld = (np.abs(x - x0 - 20) < 10) & (np.abs(y - y0 + 25) < 7.5)
    z[bld] += 8.0
    cls[bld] = 6
    # Tree crowns: 70 % of returns in the crown (class 5, first return), the rest reach
    # the ground (class 2, second return).
    for cx, cy, r in ((-30, 20, 6), (-15, 30, 5), (35, 35, 7)):
        crown = np.hypot(x - x0 - cx, y - y0 - cy) < r
        leaf = crown & (rng.uniform(size=k) < 0.7)
        z[leaf] += rng.uniform(4, 12, leaf.sum())
        cls[leaf] = 5
        ret[crown & ~leaf] = 2
    path = tmp_path / "tile.laz"
    write_las(path, np.column_stack([x, y, z]), cls, ret)
    return path


def test_ground_holdout_rmse_at_one_metre(tile):
    frame = LocalFrame(*ANCHOR)
    cloud = read_point_cloud(tile).select(ground_only=True)
    e, n, u = points_to_local(*cloud.xyz.T, cloud.crs_wkt, frame)
    rng = np.random.default_rng(1)
    hold = rng.uniform(size=len(e)) < 0.10
    train = np.column_stack([e[~hold], n[~hold], u[~hold]])
    dem = Dem.from_points(train, 1.0)
    z = dem.sample(e[hold], n[hold])
    ok = np.isfinite(z)
    resid = z[ok] - u[hold][ok]
    rmse = float(np.sqrt(np.mean(resid**2)))
    print(
        f"lidar holdout: {int(hold.sum()):,} held-out ground points, {int(ok.sum()):,} on the "
        f"model, RMSE {100 * rmse:.2f} cm, bias {100 * resid.mean():+.2f} cm, "
        f"coverage {100 * dem.coverage:.1f} %"
    )
    assert ok.mean() > 0.9  # holes only under the building and at the tile's edge
    # Floor: the held-out point's own noise (3 cm); the cell means add ~3 cm/sqrt(5)
    # and the bilinear surface a little on the slopes and hills.
    assert NOISE_M < rmse < 0.05
    assert abs(resid.mean()) < 0.005
    # The non-ground classes were kept out: with them the model would be metres off.
    all_pts = read_point_cloud(tile)
    e2, n2, u2 = points_to_local(*all_pts.xyz.T, all_pts.crs_wkt, frame)
    dsm = Dem.from_points(np.column_stack([e2, n2, u2]), 1.0)
    z2 = dsm.sample(e[hold], n[hold])
    assert np.nanmax(np.abs(z2 - u[hold])) > 2.0


def test_tin_grid_on_a_dense_tile_is_the_paper_cells_where_they_are(tile):
    from demtrack.core.terrain.tin import grid_points_tin

    frame = LocalFrame(*ANCHOR)
    cloud = read_point_cloud(tile).select(ground_only=True)
    e, n, u = points_to_local(*cloud.xyz.T, cloud.crs_wkt, frame)
    hold = np.random.default_rng(1).uniform(size=len(e)) < 0.10
    train = np.column_stack([e[~hold], n[~hold], u[~hold]])
    tin = grid_points_tin(train, 1.0)
    mean = Dem.from_points(train, 1.0, bounds=tin.dem.grid.bounds)
    z_t, z_m = tin.dem.sample(e[hold], n[hold]), mean.sample(e[hold], n[hold])
    both = np.isfinite(z_m)
    rmse_t = float(np.sqrt(np.mean((z_t[both] - u[hold][both]) ** 2)))
    rmse_m = float(np.sqrt(np.mean((z_m[both] - u[hold][both]) ** 2)))
    print(f"dense tile: TIN grid {100 * rmse_t:.2f} cm, per-cell mean {100 * rmse_m:.2f} cm")
    assert rmse_t <= 1.02 * rmse_m  # dense cells: the fit is their mean
    assert np.isfinite(z_t).mean() > np.isfinite(z_m).mean()  # and the gaps get values
    # cells under the building (no ground returns) are bridged, not left holes
    assert tin.coverage.interpolated > 0
