"""Importing a real 5 m DEM (weitsicht's dem_01, GDA94 / MGA 55, AHD): smoothing vs cell size.

The site surface is compared with the source's own bilinear surface, computed
independently (scipy's RegularGridInterpolator on the source cell centres, pyproj for the
positions). At the source's native cell the site grid is a bilinear sampling of a bilinear
surface and cuts ridges; finer cells and cubic resampling cut less (docs/site-format.md).
"""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from pyproj import Transformer
from scipy.interpolate import RegularGridInterpolator
from weitsicht_data import WEITSICHT_DIR

from demtrack.core.terrain.dem_import import (
    import_dem,
    largest_data_rectangle,
    read_raster_info,
    suggest_frame,
)
from demtrack.core.terrain.grid import GridSpec

DEM = WEITSICHT_DIR / "dem_01_gda94_mga55_ahd.tif"
pytestmark = pytest.mark.skipif(
    not DEM.is_file(), reason=f"weitsicht data not present ({WEITSICHT_DIR})"
)


@pytest.fixture(scope="module")
def source():
    with rasterio.open(DEM) as ds:
        h = ds.read(1).astype(float)
        t = ds.transform
    xs = t.c + (np.arange(h.shape[1]) + 0.5) * t.a
    ys = t.f + (np.arange(h.shape[0]) + 0.5) * t.e
    rgi = RegularGridInterpolator((ys[::-1], xs), h[::-1], bounds_error=False)
    return rgi, suggest_frame([read_raster_info(DEM)])


def misfit(source, cell, resampling):
    rgi, frame = source
    grid = GridSpec.covering(-400.0, -400.0, 400.0, 400.0, cell)
    dem = import_dem([DEM], frame, grid, resampling=resampling).dem
    assert not dem.nodata.any()
    rng = np.random.default_rng(0)
    e, n = rng.uniform(-395, 395, 20000), rng.uniform(-395, 395, 20000)
    z = dem.sample(e, n)
    lat, lon, _ = frame.to_geodetic(e, n, z)
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:28355", always_xy=True).transform(lon, lat)
    _, _, u_ref = frame.to_enu(lat, lon, rgi(np.column_stack([y, x])))
    dz = z - u_ref
    return float(np.sqrt(np.mean(dz**2))), float(np.max(np.abs(dz)))


def test_native_cell_smooths_finer_cells_and_cubic_smooth_less(source):
    native = misfit(source, 5.0, "bilinear")
    cubic = misfit(source, 5.0, "cubic")
    fine = misfit(source, 2.5, "bilinear")
    print(
        f"dem_01 vs its own surface: native 5 m {native}, cubic {cubic}, 2.5 m {fine} (RMS, max m)"
    )
    assert 0.005 < native[0] < 0.08  # real smoothing, centimetres on this terrain
    assert fine[0] < 0.5 * native[0] and fine[1] < native[1]
    assert cubic[0] < native[0]


def test_default_bounds_cut_the_warped_edges(source):
    _, frame = source
    info = read_raster_info(DEM)
    from demtrack.core.terrain.dem_import import footprint_bounds_local, grid_over

    box = grid_over(footprint_bounds_local([info], frame), 25.0)
    full = import_dem([DEM], frame, box)
    assert full.dem.nodata.any()  # the bounding box has edge holes (MGA 55 is rotated)
    r0, r1, c0, c1 = largest_data_rectangle(~full.dem.nodata)
    assert not full.dem.nodata[r0:r1, c0:c1].any()
    assert (r1 - r0) * (c1 - c0) > 0.95 * box.nrows * box.ncols
