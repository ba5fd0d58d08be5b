"""Orthometric DEMs and point clouds through a geoid evaluated at each cell's lat/lon.

Oracle: a surface defined as *ellipsoidal* heights h(lon, lat); the tile stores the
orthometric ``H = h - N(lon, lat)`` with ``N`` read from the grid independently (rasterio
+ numpy bilinear, :mod:`geoid_oracle`). Imported with the geoid model, the DEM must give
back ``h`` at every spot; with one constant ``N`` it must not (the grid's gradient is
steep on purpose: 40 m per degree of longitude, a few metres across the site).
"""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from affine import Affine
from geoid_oracle import EGM96_DEBIAN, rasterio_bilinear, write_linear_tif
from pyproj import Transformer

from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geo.geoid import GeoidModel
from demtrack.core.terrain.crs_import import points_to_local
from demtrack.core.terrain.dem_import import import_dem, read_raster_info, suggest_frame
from demtrack.core.terrain.grid import GridSpec

ANCHOR = (40.3556, -79.6225, 300.0)
UTM = "EPSG:32617"


def h_true(lon, lat):
    """Ellipsoidal test surface (m)."""
    dlon, dlat = lon - ANCHOR[1], lat - ANCHOR[0]
    return 300.0 + 700.0 * dlon - 900.0 * dlat + 1.0e5 * dlon * dlat


@pytest.fixture(scope="module")
def steep_grid(tmp_path_factory):
    path = tmp_path_factory.mktemp("geoid") / "steep.tif"
    write_linear_tif(path, -30.0 + 40.0 * 79.6225, 40.0, 0.0)  # N = -30 + 40 (lon + 79.6225)
    return path


def _utm_tile(path, n_of):
    x0, y0 = Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(*ANCHOR[1::-1])
    cell = 5.0
    transform = Affine(cell, 0.0, np.floor(x0) - 1500.0, 0.0, -cell, np.floor(y0) + 1500.0)
    cols, rows = np.meshgrid(np.arange(600) + 0.5, np.arange(600) + 0.5)
    x, y = transform @ (cols, rows)
    lon, lat = Transformer.from_crs(UTM, "EPSG:4326", always_xy=True).transform(x, y)
    big_h = h_true(lon, lat) - n_of(lat, lon)
    profile = dict(driver="GTiff", width=600, height=600, count=1, dtype="float64", crs=UTM)
    with rasterio.open(path, "w", transform=transform, **profile) as ds:
        ds.write(big_h, 1)
    return path


def _spots(frame, rng, k=40):
    lat = ANCHOR[0] + rng.uniform(-0.006, 0.006, k)
    lon = ANCHOR[1] + rng.uniform(-0.008, 0.008, k)
    return lat, lon, frame.to_enu(lat, lon, h_true(lon, lat))


def test_orthometric_tiles_through_a_national_grid_per_cell(steep_grid, tmp_path):
    frame = LocalFrame(*ANCHOR)
    model = GeoidModel.from_grid(steep_grid, "STEEP")
    tile = _utm_tile(tmp_path / "ortho.tif", lambda la, lo: rasterio_bilinear(steep_grid, la, lo))
    grid = GridSpec(-800.0, 800.0, 4.0, 400, 400)
    got = import_dem([tile], frame, grid, geoid_undulation_m=model).dem
    lat, lon, (e, n, u) = _spots(frame, np.random.default_rng(0))
    z = got.sample(e, n)
    assert np.max(np.abs(z - u)) < 0.01
    # One constant N (the anchor's) leaves the grid's gradient in: metres off at the edges.
    n0 = float(model.undulation_m(ANCHOR[0], ANCHOR[1]))
    flat = import_dem([tile], frame, grid, geoid_undulation_m=n0).dem.sample(e, n)
    assert np.max(np.abs(flat - u)) > 0.2
    # The anchor of a new site is on the terrain, in ellipsoidal height.
    f = suggest_frame([read_raster_info(tile)], geoid_undulation_m=model)
    assert f.h_m == pytest.approx(h_true(f.lon_deg, f.lat_deg), abs=0.05)


@pytest.mark.skipif(not EGM96_DEBIAN.is_file(), reason="Debian's proj-data is not installed")
def test_orthometric_tiles_through_egm96(tmp_path):
    frame = LocalFrame(*ANCHOR)
    tile = _utm_tile(tmp_path / "egm.tif", lambda la, lo: rasterio_bilinear(EGM96_DEBIAN, la, lo))
    grid = GridSpec(-800.0, 800.0, 4.0, 400, 400)
    z = import_dem([tile], frame, grid, geoid_undulation_m=GeoidModel.egm96()).dem
    lat, lon, (e, n, u) = _spots(frame, np.random.default_rng(1))
    assert np.max(np.abs(z.sample(e, n) - u)) < 0.01


def test_point_clouds_through_a_grid_per_point(steep_grid):
    frame = LocalFrame(*ANCHOR)
    model = GeoidModel.from_grid(steep_grid)
    rng = np.random.default_rng(2)
    lat = ANCHOR[0] + rng.uniform(-0.01, 0.01, 500)
    lon = ANCHOR[1] + rng.uniform(-0.01, 0.01, 500)
    x, y = Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(lon, lat)
    h = h_true(lon, lat)
    big_h_ft = (h - rasterio_bilinear(steep_grid, lat, lon)) / 0.3048
    e, n, u = points_to_local(x, y, big_h_ft, UTM, frame, geoid_undulation_m=model, z_unit_m=0.3048)
    want = frame.to_enu(lat, lon, h)
    np.testing.assert_allclose(np.stack([e, n, u]), np.stack(want), atol=1e-4)
    # A constant model goes the old way, unchanged.
    e2, n2, u2 = points_to_local(
        x, y, big_h_ft, UTM, frame, geoid_undulation_m=-33.0, z_unit_m=0.3048
    )
    np.testing.assert_allclose(u2, frame.to_enu(lat, lon, big_h_ft * 0.3048 - 33.0)[2], atol=1e-6)
