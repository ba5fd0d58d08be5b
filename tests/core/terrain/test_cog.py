"""The tiled DEM file is a Cloud-Optimized GeoTIFF: GDAL says so, and GDAL's own COGs open.

Oracles: ``gdalinfo`` (gdal-bin) and GDAL's ``validate_cloud_optimized_geotiff`` script (run
by the system Python that has GDAL's bindings; skipped where absent), the overviews against
the 2 x 2 means of the cells, and a COG made by GDAL's COG driver straight from an in-memory
DEM, whose cells ``TiledDem`` must read back unchanged.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.shutil import copy as gdal_copy

from demtrack.core.errors import DemError
from demtrack.core.raycast.pyramid import pyramid_levels_numpy
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.tiled_dem import MINMAX_TAG, TILE_TAG, TiledDem, encode_minmax
from demtrack.core.terrain.tiled_write import synth_cells, write_dem_tiled

VALIDATOR = Path(
    "/usr/lib/python3/dist-packages/osgeo_utils/samples/validate_cloud_optimized_geotiff.py"
)
SYSTEM_PYTHON = Path("/usr/bin/python3")
TILE = 128


def _dem(n: int = 1100) -> Dem:
    e = synth_cells(0, n, 0, n, seed=2)[0].copy()
    e[300:305, 500:507] = np.nan
    return Dem(GridSpec(-550.0, 550.0, 1.0, n, n), e)


def _gdalinfo(path: Path) -> str:
    if shutil.which("gdalinfo") is None:
        pytest.skip("gdalinfo (gdal-bin) is not installed")
    return subprocess.run(
        ["gdalinfo", str(path)], capture_output=True, text=True, check=True
    ).stdout


def _validate(path: Path) -> subprocess.CompletedProcess[str]:
    if not (VALIDATOR.is_file() and SYSTEM_PYTHON.is_file()):
        pytest.skip("GDAL's validate_cloud_optimized_geotiff.py is not installed")
    cmd = [str(SYSTEM_PYTHON), str(VALIDATOR), str(path)]
    return subprocess.run(cmd, capture_output=True, text=True)


def test_the_writer_makes_a_valid_cog_with_overviews(tmp_path: Path) -> None:
    dem = _dem()
    td = write_dem_tiled(dem, tmp_path / "dem.tif", tile=TILE)
    info = _gdalinfo(td.path)
    assert "LAYOUT=COG" in info
    assert "Overviews: 550x550, 275x275, 137x137, 68x68" in info  # 2x, to one tile
    run = _validate(td.path)
    assert run.returncode == 0 and "is a valid cloud optimized GeoTIFF" in run.stdout, run.stdout
    assert "warning" not in run.stdout.lower()
    assert td.overviews == (2, 4, 8, 16)
    # The cells, layers and block min/max are those written.
    np.testing.assert_array_equal(td.read_cells(0, 1100, 0, 1100), dem.elevation)
    np.testing.assert_array_equal(td.minmax, pyramid_levels_numpy(dem.elevation)[7])
    assert not list(tmp_path.glob("*partial*"))


def test_overviews_are_the_means_of_the_finite_cells_below(tmp_path: Path) -> None:
    dem = _dem()
    td = write_dem_tiled(dem, tmp_path / "dem.tif", tile=TILE)
    ov = td.read_overview(0)
    blocks = dem.elevation.reshape(550, 2, 550, 2).astype(np.float64)
    with np.errstate(invalid="ignore"), pytest.warns(RuntimeWarning):
        want = np.nanmean(blocks, axis=(1, 3))
    np.testing.assert_allclose(ov, want, rtol=0, atol=1e-4)
    # NaN only where all four cells are (a 2 x 2 with one finite cell is that cell).
    np.testing.assert_array_equal(np.isnan(ov), np.isnan(blocks).all(axis=(1, 3)))
    assert np.isnan(ov).any() and np.isnan(blocks).any(axis=(1, 3)).sum() > np.isnan(ov).sum()
    assert td.read_overview(3).shape == (68, 68)
    with pytest.raises(DemError, match="not a level 4"):
        td.read_overview(4)


def test_a_cog_made_by_gdal_opens_with_equal_cells(tmp_path: Path) -> None:
    """GDAL's COG driver, from an in-memory DEM: TiledDem reads its cells and skips overviews."""
    dem = _dem(900)
    e = dem.elevation
    info = {"tile": TILE, "z_min": float(np.nanmin(e)), "z_max": float(np.nanmax(e)), "holes": True}
    out = tmp_path / "gdal-cog.tif"
    with rasterio.open(
        "mem", "w", driver="MEM", height=900, width=900, count=1, dtype="float32",
        transform=dem.grid.transform, nodata=float("nan"),
    ) as mem:  # fmt: skip
        mem.write(e, 1)
        mem.update_tags(
            **{TILE_TAG: json.dumps(info), MINMAX_TAG: encode_minmax(pyramid_levels_numpy(e)[7])}
        )
        gdal_copy(mem, out, driver="COG", BLOCKSIZE=TILE, COMPRESS="DEFLATE", OVERVIEWS="AUTO")
    assert "LAYOUT=COG" in _gdalinfo(out)
    td = TiledDem.open(out)
    assert td.overviews == (2, 4, 8) and td.tile == TILE
    np.testing.assert_array_equal(td.read_cells(0, 900, 0, 900), e)
    np.testing.assert_array_equal(td.window_dem(100, 357, 250, 700).elevation, e[100:357, 250:700])
    out_block = np.empty((TILE + 2, TILE + 2), np.float32)
    td.read_block(2, 3, out_block)
    np.testing.assert_array_equal(out_block, e[255:385, 383:513])
