"""DEM tiles in any CRS -> site grid: analytic surfaces sampled at known points.

Oracle: a surface defined analytically in the *source* CRS (heights as a function of
lon/lat or of easting/northing), written as GeoTIFF tiles with the value of each cell at
its centre. A spot ``(x, y, H(x, y))`` in the source CRS is carried independently into
the site frame with pyproj (``LocalFrame.to_enu_from_crs``); the imported DEM sampled at
that spot's ``(e, n)`` must give its ``u``.
"""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import Transformer

from demtrack.core.errors import CrsError, DemError, InputFileError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.terrain.dem_import import (
    footprint_bounds_local,
    grid_over,
    import_dem,
    read_raster_info,
    suggest_frame,
)
from demtrack.core.terrain.grid import GridSpec

ANCHOR = (40.3573, -79.6208, 300.0)
FTUS = 1200.0 / 3937.0


@pytest.fixture(scope="module")
def frame():
    return LocalFrame(*ANCHOR)


def write_tif(path, data, transform, crs, nodata=None, units=None):
    profile = {
        "driver": "GTiff",
        "height": data.shape[0],
        "width": data.shape[1],
        "count": 1,
        "dtype": "float32",
        "transform": transform,
    }
    if crs is not None:
        profile["crs"] = crs
    if nodata is not None:
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(data.astype(np.float32), 1)
        if units:
            dst.set_band_unit(1, units)
    return path


def centres(transform, shape):
    cols, rows = np.meshgrid(np.arange(shape[1]) + 0.5, np.arange(shape[0]) + 0.5)
    return transform @ (cols, rows)


# ---------------------------------------------------------------------- geographic


def h_geo(lon, lat):
    """Orthometric-free test surface in metres over lon/lat: plane + quadratic."""
    dlon, dlat = lon - ANCHOR[1], lat - ANCHOR[0]
    return 310.0 + 900.0 * dlon - 1200.0 * dlat + 2.0e5 * dlon * dlat + 1.5e5 * dlat**2


@pytest.fixture(scope="module")
def geo_tile(tmp_path_factory):
    # A 3-arc-second WGS84 grid (SRTM style), 60 x 60 cells around the anchor.
    step = 3.0 / 3600.0
    transform = Affine(step, 0.0, ANCHOR[1] - 30 * step, 0.0, -step, ANCHOR[0] + 30 * step)
    lon, lat = centres(transform, (60, 60))
    path = tmp_path_factory.mktemp("geo") / "srtm.tif"
    return write_tif(path, h_geo(lon, lat), transform, "EPSG:4326"), transform


def test_geographic_grid_keeps_spot_heights_at_their_coordinates(frame, geo_tile):
    path, transform = geo_tile
    grid = GridSpec(-600.0, 600.0, 2.0, 600, 600)
    res = import_dem([path], frame, grid)
    # Spots at source cell centres (heights exactly as stored) and between them.
    rng = np.random.default_rng(0)
    cols = np.concatenate([rng.integers(24, 36, 10) + 0.5, rng.uniform(24, 36, 10)])
    rows = np.concatenate([rng.integers(24, 36, 10) + 0.5, rng.uniform(24, 36, 10)])
    lon, lat = transform @ (cols, rows)
    h = h_geo(lon, lat)
    e, n, u = frame.to_enu(lat, lon, h)
    z = res.dem.sample(e, n)
    # At source cell centres the stored height is exact; the 2 m target cells sample
    # the source's bilinear surface up to 1 m away from that node, where it departs from
    # the quadratic by h'' / 2 * 1 m * 92 m ~ 1.1 mm. Between source centres the
    # source's own bilinear interpolation of the quadratic adds up to ~2.5 cm.
    assert np.max(np.abs(z[:10] - u[:10])) < 2e-3
    assert np.max(np.abs(z[10:] - u[10:])) < 0.03
    # A half-cell shift (35 m east, 46 m south) would be off by 0.6 m or more on this
    # slope, 300 times the tolerance: the oracle sees it.
    lon_s, lat_s = transform @ (cols[:10] + 0.5, rows[:10] + 0.5)
    assert np.min(np.abs(h_geo(lon_s, lat_s) - h[:10])) > 0.5


def test_geographic_float_heights_in_feet_and_geoid(frame, geo_tile, tmp_path):
    _, transform = geo_tile
    lon, lat = centres(transform, (60, 60))
    n_geoid = -33.5
    path = write_tif(
        tmp_path / "ft.tif", h_geo(lon, lat) / 0.3048, transform, "EPSG:4326", units="ft"
    )
    grid = GridSpec(-100.0, 100.0, 5.0, 40, 40)
    res = import_dem([path], frame, grid, geoid_undulation_m=n_geoid)
    c, r = 30.5, 30.5
    lo, la = transform @ (c, r)
    e, n, u = frame.to_enu(la, lo, h_geo(lo, la) + n_geoid)
    z = res.dem.sample(np.array([e]), np.array([n]))[0]
    # Within 2.5 m of a source node on 5 m cells: the kink error of the source's
    # bilinear surface (~3 mm, see above); feet read as metres would be ~700 m off.
    assert abs(z - u) < 5e-3


# ---------------------------------------------------------------------- projected


def h_sp(x_ft, y_ft, x0, y0):
    """State-plane test surface, heights in US survey feet over ftUS coordinates."""
    dx, dy = x_ft - x0, y_ft - y0
    return 1000.0 + 0.05 * dx - 0.08 * dy + 2e-5 * dx * dy


def test_state_plane_us_survey_feet_orthometric(frame, tmp_path):
    crs = "EPSG:2272"  # NAD83 / Pennsylvania South (ftUS)
    x0, y0 = Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(ANCHOR[1], ANCHOR[0])
    cell = 10.0  # ftUS
    transform = Affine(cell, 0.0, np.floor(x0) - 2000.0, 0.0, -cell, np.floor(y0) + 2000.0)
    x, y = centres(transform, (400, 400))
    path = write_tif(tmp_path / "sp.tif", h_sp(x, y, x0, y0), transform, crs)
    assert read_raster_info(path).z_unit_m() == pytest.approx(FTUS)
    grid = GridSpec(-400.0, 400.0, 1.0, 800, 800)
    res = import_dem([path], frame, grid, geoid_undulation_m=-33.5)
    rng = np.random.default_rng(1)
    xs = x0 + rng.uniform(-1200, 1200, 30)
    ys = y0 + rng.uniform(-1200, 1200, 30)
    e, n, u = frame.to_enu_from_crs(
        xs, ys, h_sp(xs, ys, x0, y0), crs, geoid_undulation_m=-33.5, z_unit_m=FTUS
    )
    z = res.dem.sample(e, n)
    assert np.max(np.abs(z - u)) < 2e-3
    # Feet read as metres, or the geoid forgotten, is caught.
    assert np.max(np.abs(z - (u + 33.5))) > 30.0


@pytest.fixture(scope="module")
def utm_surface(frame):
    crs = "EPSG:32617"
    x0, y0 = Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(ANCHOR[1], ANCHOR[0])
    x0, y0 = float(np.floor(x0)), float(np.floor(y0))

    def h(x, y):
        return 300.0 + 0.1 * (x - x0) + 0.05 * (y - y0) + 1e-4 * (x - x0) ** 2

    return crs, x0, y0, h


def test_tiles_mosaic_without_a_seam_and_holes_fill_from_coarse(frame, utm_surface, tmp_path):
    crs, x0, y0, h = utm_surface
    cell = 2.0
    transform = Affine(cell, 0.0, x0 - 300.0, 0.0, -cell, y0 + 300.0)
    x, y = centres(transform, (300, 300))
    full = h(x, y)
    whole = write_tif(tmp_path / "whole.tif", full, transform, crs)
    # Two tiles sharing the edge at column 150; the east one has a nodata hole.
    west = write_tif(tmp_path / "w.tif", full[:, :150], transform, crs)
    east_data = full[:, 150:].copy()
    east_data[100:120, 20:40] = -9999.0
    t_east = transform @ Affine.translation(150, 0)
    east = write_tif(tmp_path / "e.tif", east_data, t_east, crs, nodata=-9999.0)
    # Coarse fallback: 30 m cells of the same surface, in geographic degrees.
    step = 1.0 / 3600.0
    t_c = Affine(step, 0.0, ANCHOR[1] - 20 * step, 0.0, -step, ANCHOR[0] + 20 * step)
    lon_c, lat_c = centres(t_c, (40, 40))
    xc, yc = Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(lon_c, lat_c)
    coarse = write_tif(tmp_path / "coarse.tif", h(xc, yc), t_c, "EPSG:4326")

    grid = GridSpec(-250.0, 250.0, 1.0, 500, 500)
    ref = import_dem([whole], frame, grid)
    mos = import_dem([east, west], frame, grid, coarse=coarse, coarse_sigma_m=3.0)
    assert mos.groups == ((0, 1),)  # one lattice: merged before warping
    hole = ~np.isfinite(
        import_dem([east, west], frame, grid).dem.elevation
    )  # without the coarse DEM only the nodata patch is empty
    assert 200 < hole.sum() < 2000
    assert ref.hole_cells == 0 and mos.hole_cells == 0
    # Outside the hole the mosaic equals the single raster: no seam.
    ok = ~hole
    assert np.max(np.abs(mos.dem.elevation[ok] - ref.dem.elevation[ok])) < 1e-4
    assert mos.filled_cells == int(hole.sum())
    assert np.array_equal(mos.dem.filled, hole)
    assert np.allclose(mos.dem.variance[hole], 9.0)
    # Filled cells come from the coarse surface: the same function, so close to it.
    assert np.max(np.abs(mos.dem.elevation[hole] - ref.dem.elevation[hole])) < 0.1
    assert sum(mos.tile_cells) == grid.nrows * grid.ncols - mos.filled_cells
    assert all(c > 0 for c in mos.tile_cells)


def test_tiles_of_different_crs_are_warped_separately(frame, utm_surface, geo_tile, tmp_path):
    crs, x0, y0, h = utm_surface
    transform = Affine(2.0, 0.0, x0 - 100.0, 0.0, -2.0, y0 + 100.0)
    x, y = centres(transform, (100, 100))
    utm = write_tif(tmp_path / "u.tif", h(x, y), transform, crs)
    geo, _ = geo_tile
    grid = GridSpec(-500.0, 500.0, 5.0, 200, 200)
    res = import_dem([utm, geo], frame, grid)
    assert res.groups == ((0,), (1,))
    assert res.tile_cells[0] > 0 and res.tile_cells[1] > res.tile_cells[0]
    # The first listed wins where both cover: at the anchor the value is UTM's.
    e, n, u = frame.to_enu_from_crs(x0 + 1.0, y0 + 1.0, h(x0 + 1.0, y0 + 1.0), crs)
    assert abs(res.dem.sample(np.array([e]), np.array([n]))[0] - u) < 1e-3


def test_new_site_frame_and_grid_from_footprint(frame, geo_tile):
    path, _ = geo_tile
    info = read_raster_info(path)
    f = suggest_frame([info])
    assert abs(f.lat_deg - ANCHOR[0]) < 1e-6 and abs(f.lon_deg - ANCHOR[1]) < 1e-6
    assert abs(f.h_m - h_geo(ANCHOR[1], ANCHOR[0])) < 10.0
    b = footprint_bounds_local([info], f)
    # 59 cell spacings of 3" between the outer centres: ~1.82 km N-S, ~1.39 km E-W.
    assert b[3] - b[1] == pytest.approx(59 * 3 / 3600 * 111_040, rel=2e-3)
    g = grid_over(b, 50.0)
    assert g.x_min <= b[0] and g.x_max >= b[2] and g.x_min % 50.0 == 0.0


def test_bad_tiles_are_one_line_errors(frame, tmp_path):
    data = np.zeros((10, 10))
    no_crs = write_tif(tmp_path / "nocrs.tif", data, Affine(1, 0, 0, 0, -1, 10), None)
    with pytest.raises(CrsError, match="has no CRS") as err:
        import_dem([no_crs], frame, GridSpec(0, 10, 1, 10, 10))
    assert "\n" not in str(err.value)
    (tmp_path / "junk.tif").write_bytes(b"not a tiff")
    with pytest.raises(InputFileError, match="cannot read raster"):
        import_dem([tmp_path / "junk.tif"], frame, GridSpec(0, 10, 1, 10, 10))
    far = write_tif(
        tmp_path / "far.tif", data + 5.0, Affine(1e-4, 0, 10.0, 0, -1e-4, 50.0), "EPSG:4326"
    )
    with pytest.raises(DemError, match="do not reach the site grid"):
        import_dem([far], frame, GridSpec(0, 10, 1, 10, 10))
