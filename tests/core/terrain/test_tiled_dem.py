"""The tiled DEM file: round trip of cells and layers, block min/max against the pyramid, reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio

from demtrack.core.errors import DemError, InputFileError
from demtrack.core.raycast.pyramid import pyramid_levels_numpy
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.tiled_dem import TiledDem
from demtrack.core.terrain.tiled_write import (
    synth_cells,
    synth_tiled,
    tile_geotiff,
    write_dem_tiled,
)


def _dem(nrows: int = 300, ncols: int = 257) -> Dem:
    rng = np.random.default_rng(0)
    e = synth_cells(0, nrows, 0, ncols)[0].copy()
    e[40:43, 60:62] = np.nan
    var = rng.uniform(0, 1, e.shape).astype(np.float32)
    var[np.isnan(e)] = np.nan
    count = rng.integers(0, 9, e.shape).astype(np.int32)
    filled = np.zeros(e.shape, bool)
    filled[200:210, 10:30] = True
    count[filled] = 0  # as Dem.write stores a filled cell (its count is NaN on disk)
    return Dem(GridSpec(100.0, 900.0, 0.5, nrows, ncols), e, var, count, filled)


@pytest.mark.parametrize("compress", ["deflate", "zstd"])
def test_round_trip_keeps_every_layer_and_the_block_minmax(tmp_path: Path, compress: str) -> None:
    dem = _dem()
    td = write_dem_tiled(dem, tmp_path / "t.tif", tile=64, compress=compress, chunk_tiles=2)
    back = Dem.read(tmp_path / "t.tif")
    for name in ("elevation", "variance", "count", "filled"):
        np.testing.assert_array_equal(getattr(back, name), getattr(dem, name), err_msg=name)
    assert back.grid == dem.grid and td.grid == dem.grid
    # Level 6 of the pyramid (64-patch blocks), holes as (+inf, -inf).
    np.testing.assert_array_equal(td.minmax, pyramid_levels_numpy(dem.elevation)[6])
    assert (
        td.holes and td.z_min == np.nanmin(dem.elevation) and td.z_max == np.nanmax(dem.elevation)
    )
    with rasterio.open(tmp_path / "t.tif") as src:
        assert src.block_shapes[0] == (64, 64) and src.compression.value.lower() == compress


def test_windows_blocks_and_samples_read_only_what_they_need(tmp_path: Path) -> None:
    dem = _dem()
    td = write_dem_tiled(dem, tmp_path / "t.tif", tile=32)
    np.testing.assert_array_equal(td.read_cells(10, 50, 200, 257), dem.elevation[10:50, 200:257])
    out = np.empty((34, 34), np.float32)
    shape = td.read_block(0, 7, out)  # the last block column: 257 - 224 = 33 cells
    assert shape == (33, 33)
    np.testing.assert_array_equal(out[1:34, 1:34], dem.elevation[0:33, 224:257])
    assert np.isnan(out[0]).all()  # the halo row above the grid
    np.testing.assert_array_equal(out[1:34, 0], dem.elevation[0:33, 223])  # the halo column
    win = td.window_dem(5, 60, 7, 90)
    np.testing.assert_array_equal(win.elevation, dem.elevation[5:60, 7:90])
    assert win.grid.x_min == dem.grid.x_min + 7 * 0.5
    rng = np.random.default_rng(1)
    x0, y0, x1, y1 = dem.grid.bounds
    x, y = rng.uniform(x0 - 5, x1 + 5, 3000), rng.uniform(y0 - 5, y1 + 5, 3000)
    np.testing.assert_array_equal(td.sample(x, y), dem.sample(x, y))
    np.testing.assert_array_equal(td.sample_variance(x, y), dem.sample_variance(x, y))
    for a, b in zip(td.gradient(x, y), dem.gradient(x, y), strict=True):
        np.testing.assert_array_equal(a, b)


def test_tile_geotiff_from_a_single_band_file_with_a_nodata_value(tmp_path: Path) -> None:
    e = synth_cells(0, 90, 0, 70)[0].copy()
    e[3, 4] = -9999.0
    g = GridSpec(0.0, 90.0, 1.0, 90, 70)
    src = tmp_path / "in.tif"
    with rasterio.open(src, "w", driver="GTiff", height=90, width=70, count=1,
                       dtype="float32", transform=g.transform, nodata=-9999.0) as dst:  # fmt: skip
        dst.write(e, 1)
    td = tile_geotiff(src, tmp_path / "out.tif", tile=16)
    cells = td.read_cells(0, 90, 0, 70)
    assert np.isnan(cells[3, 4]) and td.holes and td.bands == 1
    e[3, 4] = np.nan
    np.testing.assert_array_equal(cells, e)


def test_synth_is_the_same_whatever_the_chunks(tmp_path: Path) -> None:
    a = synth_tiled(tmp_path / "a.tif", 300, tile=32, chunk_tiles=1)
    b = synth_tiled(tmp_path / "b.tif", 300, tile=64, chunk_tiles=3)
    np.testing.assert_array_equal(a.read_cells(0, 300, 0, 300), b.read_cells(0, 300, 0, 300))
    np.testing.assert_array_equal(a.read_cells(0, 300, 0, 300), synth_cells(0, 300, 0, 300)[0])


def test_bad_inputs_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(DemError, match="power of two"):
        synth_tiled(tmp_path / "x.tif", 100, tile=100)
    with pytest.raises(DemError, match="compress"):
        synth_tiled(tmp_path / "x.tif", 100, tile=32, compress="lzma")
    with pytest.raises(InputFileError, match="does not exist"):
        TiledDem.open(tmp_path / "none.tif")
    _dem().write(tmp_path / "plain.tif")
    with pytest.raises(InputFileError, match="no block min/max"):
        TiledDem.open(tmp_path / "plain.tif")
    (tmp_path / "junk.tif").write_bytes(b"not a tiff")
    with pytest.raises(InputFileError, match="cannot read"):
        TiledDem.open(tmp_path / "junk.tif")
    td = synth_tiled(tmp_path / "ok.tif", 100, tile=32)
    with pytest.raises(DemError, match="outside"):
        td.read_cells(0, 101, 0, 10)
