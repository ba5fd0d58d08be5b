"""Warping rasters and points from projected/geographic CRSs into the site frame.

Oracle: a terrain defined analytically in the local frame, Z = g(e, n). The source DEMs are
built the other way round from the code under test: for each source cell centre (x, y),
pyproj gives its lat/lon, and a Newton solve with an independent numpy ECEF/ENU twin finds
the ellipsoidal height where the ellipsoid normal there meets the surface Z = g(e, n).
Warping that DEM back must reproduce g at every local cell centre.
"""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS, Transformer
from wgs84_twin import enu

from demtrack.core.errors import CrsError, DemError, InputFileError
from demtrack.core.geo.geodesy import LocalFrame, meridian_convergence_deg
from demtrack.core.terrain.crs_import import (
    bilinear_at_centres,
    image_to_rgba,
    local_crs_wkt,
    points_to_local,
    read_raster_to_local,
    warp_to_local,
)
from demtrack.core.terrain.grid import GridSpec

# Bushy Run Battlefield, PA: 40.357 N, 79.621 W -> UTM zone floor((180 - 79.62) / 6) + 1 = 17.
BUSHY_RUN = (40.3573, -79.6208, 300.0)
FTUS = 1200.0 / 3937.0


def _enu(lat_deg, lon_deg, h_m, anchor=BUSHY_RUN):
    return enu(lat_deg, lon_deg, h_m, anchor)


def terrain(e, n):
    """Local-frame Z (m): a tilted plane (slopes 0.2 / -0.1) plus +-15 m of hills."""
    return (
        20.0
        + 0.2 * e
        - 0.1 * n
        + 15.0 * np.sin(2 * np.pi * e / 1500.0) * np.cos(2 * np.pi * n / 1700.0)
    )


def make_dem(crs, cell, half_m, *, z_unit_m=1.0, geoid_undulation_m=0.0):
    """Source DEM in ``crs`` around the anchor: heights H = (h - N) / z_unit at centres."""
    unit = CRS(crs).axis_info[0].unit_conversion_factor
    to_src = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x0, y0 = to_src.transform(BUSHY_RUN[1], BUSHY_RUN[0])
    half = half_m / unit
    transform = Affine(cell, 0.0, np.floor(x0 - half), 0.0, -cell, np.ceil(y0 + half))
    ncells = int(2 * half / cell)
    cols, rows = np.meshgrid(np.arange(ncells) + 0.5, np.arange(ncells) + 0.5)
    x, y = transform @ (cols, rows)
    lon, lat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(x, y)
    h = np.full(x.shape, BUSHY_RUN[2])
    for _ in range(6):  # Newton on F(h) = u(h) - g(e(h), n(h)) along each normal
        e, n, u = _enu(lat, lon, h)
        e1, n1, u1 = _enu(lat, lon, h + 1.0)
        f0, f1 = u - terrain(e, n), u1 - terrain(e1, n1)
        h = h - f0 / (f1 - f0)
    assert np.max(np.abs(_enu(lat, lon, h)[2] - terrain(*_enu(lat, lon, h)[:2]))) < 1e-6
    return (h - geoid_undulation_m) / z_unit_m, transform


@pytest.fixture(scope="module")
def frame():
    return LocalFrame(*BUSHY_RUN)


@pytest.fixture(scope="module")
def utm_dem():
    return make_dem("EPSG:32617", 5.0, 1300.0)


GRID = GridSpec(-1000.0, 1000.0, 10.0, 200, 200)  # +-1 km around the anchor, 10 m cells


def test_utm_dem_matches_analytic_surface(frame, utm_dem):
    h, transform = utm_dem
    z = warp_to_local(h, transform, "EPSG:32617", frame, GRID)
    assert z.dtype == np.float32 and z.shape == GRID.shape
    e, n = GRID.centres()
    err = np.abs(z - terrain(e, n))
    assert not np.any(np.isnan(z))
    # Bilinear interpolation of 5 m source cells over the hills costs ~1.5 mm.
    assert err.max() < 0.01


def test_convergence_is_handled_and_shift_only_is_not(frame, utm_dem):
    h, transform = utm_dem
    gamma = meridian_convergence_deg("EPSG:32617", *BUSHY_RUN[:2])
    assert 0.85 < gamma < 0.95  # vs the zone's central meridian, -81 deg
    e, n = GRID.centres()
    proper = warp_to_local(h, transform, "EPSG:32617", frame, GRID)
    # The naive import: translate UTM so the anchor is at 0, keep axes and scale.
    x0, y0 = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(
        BUSHY_RUN[1], BUSHY_RUN[0]
    )
    naive = bilinear_at_centres(h, transform, x0 + e, y0 + n) - BUSHY_RUN[2]
    assert np.max(np.abs(proper - terrain(e, n))) < 0.01
    assert np.max(np.abs(naive - terrain(e, n))) > 2.0
    # Where the naive import puts things: 0.9 deg * 1.4 km = 22 m off at the corners.
    x_true, y_true, _ = frame.from_enu_to_crs(e, n, terrain(e, n), "EPSG:32617")
    assert np.max(np.hypot(x_true - (x0 + e), y_true - (y0 + n))) > 15.0


def test_height_iteration_residual(frame, utm_dem):
    h, transform = utm_dem
    z = warp_to_local(h, transform, "EPSG:32617", frame, GRID).astype(np.float64)
    e, n = GRID.centres()
    lat, lon, h_pt = frame.to_geodetic(e, n, z)
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(lon, lat)
    residual = bilinear_at_centres(h, transform, x, y) - h_pt
    assert np.max(np.abs(residual)) < 1e-4  # float32 output rounding dominates
    # One iteration only leaves the d/R tilt of the vertical uncorrected: centimetres.
    z1 = warp_to_local(h, transform, "EPSG:32617", frame, GRID, max_iter=1)
    assert 0.005 < np.max(np.abs(z1 - terrain(e, n))) < 0.05


def test_state_plane_us_survey_feet(frame):
    # NAD83 / Pennsylvania South (ftUS); orthometric heights in ftUS with N = -33.5 m.
    h_ft, transform = make_dem("EPSG:2272", 15.0, 1300.0, z_unit_m=FTUS, geoid_undulation_m=-33.5)
    assert 1000.0 < np.median(h_ft) < 1200.0  # (300 + 33.5) m in feet
    z = warp_to_local(h_ft, transform, "EPSG:2272", frame, GRID, geoid_undulation_m=-33.5)
    e, n = GRID.centres()
    assert np.max(np.abs(z - terrain(e, n))) < 0.01
    # Same through a compound CRS whose vertical axis states the unit.
    z2 = warp_to_local(h_ft, transform, "EPSG:2272+6360", frame, GRID, geoid_undulation_m=-33.5)
    assert np.max(np.abs(z2 - z)) < 1e-5
    # Reading feet as metres is caught by the oracle (heights off by hundreds of metres).
    z_bad = warp_to_local(
        h_ft, transform, "EPSG:2272", frame, GRID, z_unit_m=1.0, geoid_undulation_m=-33.5
    )
    assert np.nanmax(np.abs(z_bad - terrain(e, n))) > 100.0


def test_geographic_arc_second_grid_has_no_half_cell_shift(frame):
    # A 3-arc-second NAD83 geographic DEM (USGS style) of rough random heights: each spot
    # height must come back at its own coordinates. NAD83 -> WGS84 is PROJ's null
    # transformation offline, so lat/lon are shared with the frame.
    rng = np.random.default_rng(0)
    step = 3.0 / 3600.0
    transform = Affine(step, 0.0, -79.65, 0.0, -step, 40.38)
    h = 300.0 + rng.normal(0.0, 5.0, (60, 60))
    rows = rng.integers(2, 58, 12)
    cols = rng.integers(2, 58, 12)
    for r, c in zip(rows, cols, strict=True):
        lon, lat = transform @ (c + 0.5, r + 0.5)
        e, n, u = frame.to_enu(lat, lon, h[r, c])
        one = GridSpec(e - 0.5, n + 0.5, 1.0, 1, 1)  # a single cell centred on the spot
        z = warp_to_local(h, transform, "EPSG:4269", frame, one)
        assert abs(z[0, 0] - u) < 1e-4, (r, c)
    # A half-cell shift would have sampled between neighbours: metres off here.
    lon, lat = transform @ (cols[0] + 1.0, rows[0] + 1.0)
    e, n, u = frame.to_enu(lat, lon, h[rows[0], cols[0]])
    z = warp_to_local(h, transform, "EPSG:4269", frame, GridSpec(e - 0.5, n + 0.5, 1.0, 1, 1))
    corners = h[rows[0] : rows[0] + 2, cols[0] : cols[0] + 2].mean() - h[rows[0], cols[0]]
    assert abs((z[0, 0] - u) - corners) < 0.05


def test_nodata_and_coverage(frame, utm_dem):
    h, transform = utm_dem
    h = h.copy()
    h[200:220, 250:260] = -9999.0
    grid = GridSpec(-1500.0, 1500.0, 20.0, 150, 150)  # wider than the 1.3 km source
    z = warp_to_local(h, transform, "EPSG:32617", frame, grid, src_nodata=-9999.0)
    e, n = grid.centres()
    assert np.isnan(z[0, 0]) and np.isnan(z[-1, -1])
    assert np.isfinite(z[75, 75])
    # Cells whose sampling patch touches the hole are NaN, the others are untouched.
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(
        *frame.to_geodetic(e, n, np.nan_to_num(z))[1::-1]
    )
    col, row = ~transform @ (x, y)
    in_hole = (col - 0.5 > 249) & (col - 0.5 < 260) & (row - 0.5 > 199) & (row - 0.5 < 220)
    assert np.all(np.isnan(z[in_hole]))
    ok = np.isfinite(z)
    assert ok.sum() > 0.5 * z.size
    assert np.max(np.abs(z[ok] - terrain(e, n)[ok])) < 0.01
    masked = np.ma.masked_equal(h, -9999.0)
    z2 = warp_to_local(masked, transform, "EPSG:32617", frame, grid)
    np.testing.assert_array_equal(np.isnan(z2), np.isnan(z))


def test_image_bands_bilinear(frame):
    # uint8 RGB orthophoto in UTM whose bands are linear in x/y (bilinear reproduces
    # linear functions exactly; only the uint8 rounding of the source remains).
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True)
    x0, y0 = to_utm.transform(BUSHY_RUN[1], BUSHY_RUN[0])
    transform = Affine(0.5, 0.0, np.floor(x0 - 40.0), 0.0, -0.5, np.ceil(y0 + 40.0))
    cols, rows = np.meshgrid(np.arange(160) + 0.5, np.arange(160) + 0.5)
    x, y = transform @ (cols, rows)

    def bands(x, y):
        return np.stack([128 + 2.0 * (x - x0), 128 - 2.0 * (y - y0), 100 + (x - x0) + (y - y0)])

    rgb = np.clip(np.rint(bands(x, y)), 0, 255).astype(np.uint8)
    grid = GridSpec(-30.0, 30.0, 0.25, 240, 240)
    out = warp_to_local(rgb, transform, "EPSG:32617", frame, grid, kind="image", z_local=0.0)
    assert out.shape == (3, 240, 240) and out.dtype == np.float32
    e, n = grid.centres()
    xs, ys, _ = frame.from_enu_to_crs(e, n, 0.0, "EPSG:32617")
    assert np.max(np.abs(out - bands(xs, ys))) < 0.51
    rgba = image_to_rgba(out)
    assert rgba.shape == (240, 240, 4) and rgba.dtype == np.uint8
    assert np.all(rgba[..., 3] == 255)
    grey = warp_to_local(rgb[0], transform, "EPSG:32617", frame, grid, kind="image")
    assert grey.shape == (240, 240)
    wide = GridSpec(-60.0, 60.0, 1.0, 120, 120)
    holes = image_to_rgba(warp_to_local(rgb, transform, "EPSG:32617", frame, wide, kind="image"))
    assert holes[0, 0, 3] == 0 and holes[60, 60, 3] == 255


def _write_tif(path, data, transform, crs, nodata=None, units=None):
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=data.shape[1],
        height=data.shape[0],
        count=1,
        dtype=data.dtype,
        crs=crs,
        transform=transform,
        nodata=nodata,
    ) as dst:
        dst.write(data, 1)
        if units:
            dst.units = (units,)


def test_read_raster_to_local(tmp_path, frame, utm_dem):
    h, transform = utm_dem
    data = h.astype(np.float32)
    data[:5, :5] = -32768.0
    path = tmp_path / "dem_utm.tif"
    _write_tif(path, data, transform, "EPSG:32617", nodata=-32768.0)
    grid = GridSpec(-500.0, 400.0, 10.0, 80, 90)  # a window of the file is read
    z = read_raster_to_local(path, frame, grid)
    e, n = grid.centres()
    assert np.max(np.abs(z - terrain(e, n))) < 0.01
    ref = warp_to_local(data, transform, "EPSG:32617", frame, grid, src_nodata=-32768.0)
    np.testing.assert_allclose(z, ref, rtol=0, atol=1e-5)
    far = read_raster_to_local(path, frame, GridSpec(5000.0, 5100.0, 10.0, 10, 10))
    assert far.shape == (10, 10) and np.all(np.isnan(far))
    # A band unit tag wins over the CRS default (feet in a metre CRS).
    path_ft = tmp_path / "dem_utm_ft.tif"
    _write_tif(path_ft, (h / 0.3048).astype(np.float32), transform, "EPSG:32617", units="ft")
    z_ft = read_raster_to_local(path_ft, frame, grid)
    assert np.max(np.abs(z_ft - terrain(e, n))) < 0.01


def test_missing_crs_raises(tmp_path, frame, utm_dem):
    h, transform = utm_dem
    path = tmp_path / "no_crs.tif"
    _write_tif(path, h[:50, :50].astype(np.float32), transform, None)
    with pytest.raises(CrsError, match="has no CRS"):
        read_raster_to_local(path, frame, GRID)
    with pytest.raises(CrsError, match="no CRS"):
        warp_to_local(h, transform, None, frame, GRID)
    with pytest.raises(InputFileError, match="cannot read"):
        read_raster_to_local(tmp_path / "missing.tif", frame, GRID)
    with pytest.raises(DemError, match="kind"):
        warp_to_local(h, transform, "EPSG:32617", frame, GRID, kind="lidar")


def test_points_to_local(frame):
    rng = np.random.default_rng(3)
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True)
    x0, y0 = to_utm.transform(BUSHY_RUN[1], BUSHY_RUN[0])
    x = x0 + rng.uniform(-800, 800, 1000)
    y = y0 + rng.uniform(-800, 800, 1000)
    z = rng.uniform(250.0, 350.0, 1000)  # orthometric, N = -33.5 m
    lon, lat = Transformer.from_crs("EPSG:32617", "EPSG:4326", always_xy=True).transform(x, y)
    ref = _enu(lat, lon, z - 33.5)
    e, n, u = points_to_local(x, y, z, "EPSG:32617", frame, geoid_undulation_m=-33.5)
    assert e.shape == (1000,)
    assert np.max(np.abs(np.stack([e, n, u]) - ref)) < 1e-3
    with pytest.raises(CrsError, match="no CRS"):
        points_to_local(x, y, z, None, frame)


def test_local_crs_matches_enu_on_the_ground(tmp_path, frame):
    wkt = local_crs_wkt(frame)
    crs = CRS.from_wkt(wkt)
    assert crs.is_projected
    to_local = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    rng = np.random.default_rng(4)
    e = rng.uniform(-2000.0, 2000.0, 500)
    n = rng.uniform(-2000.0, 2000.0, 500)
    for dz, tol in [(0.0, 1e-5), (100.0, 0.05), (-100.0, 0.05)]:
        # Points at ellipsoidal height h0 + dz above the local (e, n).
        lat, lon, _ = frame.to_geodetic(e, n, 0.0)
        lat, lon, _ = frame.to_geodetic(*frame.to_enu(lat, lon, BUSHY_RUN[2] + dz)[:2], 0.0)
        ee, nn, _ = frame.to_enu(lat, lon, BUSHY_RUN[2] + dz)
        x, y = to_local.transform(lon, lat)
        assert np.max(np.hypot(x - ee, y - nn)) < tol
        if dz:
            assert np.max(np.hypot(x - ee, y - nn)) > 0.02  # the stated dz * d / R
    # Plain WGS84 orthographic: exact on the ellipsoid, 13 cm off at 300 m / 2.8 km.
    crs0 = CRS.from_wkt(local_crs_wkt(frame, surface_h_m=0.0))
    assert crs0.datum.name == "World Geodetic System 1984"
    lat, lon = np.array([40.37, 40.34]), np.array([-79.60, -79.64])
    ee, nn, _ = frame.to_enu(lat, lon, 0.0)
    x, y = Transformer.from_crs("EPSG:4326", crs0, always_xy=True).transform(lon, lat)
    assert np.max(np.hypot(x - ee, y - nn)) < 1e-5
    # It survives a GeoTIFF round trip (GDAL writes it as GeoTIFF keys / WKT1).
    path = tmp_path / "site.tif"
    _write_tif(path, np.zeros((3, 4), np.float32), GRID.transform, rasterio.crs.CRS.from_wkt(wkt))
    with rasterio.open(path) as ds:
        back = CRS.from_wkt(ds.crs.to_wkt())
    xb, yb = Transformer.from_crs("EPSG:4326", back, always_xy=True).transform(lon, lat)
    x, y = to_local.transform(lon, lat)
    assert np.max(np.hypot(xb - x, yb - y)) < 1e-6


def test_geographic_raster_across_the_antimeridian():
    # Anchor at lon 179.999; the DEM is stored with longitudes 179.99 .. 180.01 (GDAL
    # allows x > 180). Cells east of the antimeridian (lon -179.99x) must still find it.
    anchor = (40.0, 179.999, 10.0)
    frame = LocalFrame(*anchor)
    step = 1.0 / 3600.0
    transform = Affine(step, 0.0, 179.99, 0.0, -step, 40.01)
    cols, rows = np.meshgrid(np.arange(72) + 0.5, np.arange(72) + 0.5)
    lon, lat = transform @ (cols, rows)
    h = 10.0 + 1000.0 * (lon - 180.0) + 500.0 * (lat - 40.0)  # a plane in lon/lat
    grid = GridSpec(-400.0, 400.0, 20.0, 40, 40)  # straddles lon 180 (e ~ +85 m)
    z = warp_to_local(h, transform, "EPSG:4326", frame, grid)
    assert not np.any(np.isnan(z))
    e, n = grid.centres()
    lat_c, lon_c, h_c = frame.to_geodetic(e, n, z.astype(np.float64))
    assert lon_c.min() < -179.99 and lon_c.max() > 179.99
    lon_c = np.where(lon_c < 0, lon_c + 360.0, lon_c)
    expected = 10.0 + 1000.0 * (lon_c - 180.0) + 500.0 * (lat_c - 40.0)
    assert np.max(np.abs(h_c - expected)) < 1e-3
