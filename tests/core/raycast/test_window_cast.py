"""Windowed in-memory casts in the whole DEM's frame: bit for bit the tiled and the whole-DEM casts.

A window read into its own ``Dem`` casts with another grid origin and pyramid, so its hit
points differ from the whole DEM's by rounding; ``WindowRayCaster`` keeps the whole DEM's
frame. The oracles are ``RayCaster`` over the whole DEM and ``TiledRayCaster`` (both bit for
bit), on cameras next to block seams and window edges, over holes on seams.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from raycast_checks import assert_identical_hits

from demtrack.core.errors import RaycastError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.raycast.tile_cache import slot_bytes
from demtrack.core.raycast.tiled_cast import TiledRayCaster
from demtrack.core.raycast.window_cast import WindowRayCaster
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.tiled_dem import TiledDem
from demtrack.core.terrain.tiled_write import synth_cells, write_dem_tiled

TILE = 64
N = 700
REACH = 150.0


@pytest.fixture(scope="module")
def dem() -> Dem:
    e = synth_cells(0, N, 0, N, seed=5)[0].copy()
    e[120:140, 100:160] = 290.0  # a roof across the seam column 128
    e[192:194, 300:330] = np.nan  # a hole on the seam row 192
    e[383:386, 383:386] = np.nan  # and at the block corner (384, 384)
    # An odd-sized grid whose origin is not a multiple of the cell: every offset rounds.
    grid = GridSpec(-351.3, 347.7, 1.0, N, N)
    return Dem(grid, e)


@pytest.fixture(scope="module")
def tiled(dem: Dem, tmp_path_factory: pytest.TempPathFactory) -> TiledDem:
    return write_dem_tiled(dem, tmp_path_factory.mktemp("win") / "dem.tif", tile=TILE)


def _fan(dem: Dem, cell: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A camera's pixel rays, 30 m above the terrain at grid position ``cell``."""
    x, y = (float(v) for v in dem.grid.from_grid(np.float64(cell[0]), np.float64(cell[1])))
    z = float(dem.sample(np.array([x]), np.array([y]))[0]) + 30.0
    a, e = np.meshgrid(np.linspace(0, 2 * np.pi, 90, endpoint=False), np.linspace(-0.7, -0.01, 12))
    d = np.c_[(np.cos(e) * np.cos(a)).ravel(), (np.cos(e) * np.sin(a)).ravel(), np.sin(e).ravel()]
    return np.tile([x, y, z], (len(d), 1)), d


# Cameras on seams, at block corners, by the DEM's edge and in the middle of a block.
CAMERAS = [(128, 192), (384, 376), (200.37, 64.5), (10.2, 690.4), (500.0, 317.25)]


@pytest.mark.parametrize("cell", CAMERAS)
def test_windowed_cast_is_bit_identical_to_the_tiled_and_whole_casts(
    tiled: TiledDem, dem: Dem, cell: tuple[float, float]
) -> None:
    o, d = _fan(dem, cell)
    win = WindowRayCaster.for_rays(tiled, o, d, REACH)
    r0, r1, c0, c1 = win.window
    assert (r1 - r0) * (c1 - c0) < N * N / 3  # a window, not the DEM
    assert r0 % TILE == 0 and c0 % TILE == 0
    got = win.cast(o, d, REACH)
    whole = RayCaster.from_dem(SimpleNamespace(grid=dem.grid, elevation=dem.elevation))
    assert_identical_hits(got, whole.cast(o, d, REACH, coherent=False))
    tc = TiledRayCaster(tiled, 4 * slot_bytes(TILE))
    assert_identical_hits(got, tc.cast(o, d, REACH))
    assert got.hit.sum() > len(o) // 6  # a camera by the corner sees a quarter of the DEM


def test_rays_over_holes_and_first_mode(tiled: TiledDem, dem: Dem) -> None:
    o, d = _fan(dem, (390.5, 380.0))
    win = WindowRayCaster.for_rays(tiled, o, d, REACH)
    tc = TiledRayCaster(tiled, 9 * slot_bytes(TILE))
    for mode, max_hits in (("all", 256), ("first", 1), ("all", 2)):
        got = win.cast(o, d, REACH, mode=mode, max_hits=max_hits)
        assert_identical_hits(got, tc.cast(o, d, REACH, mode=mode, max_hits=max_hits))
    assert win.cast(o, d, REACH).crossed_nodata.any()


def test_own_window_dem_rounds_differently_and_rays_past_the_window_are_refused(
    tiled: TiledDem, dem: Dem
) -> None:
    o, d = _fan(dem, (300.3, 250.6))
    win = WindowRayCaster.for_rays(tiled, o, d, REACH)
    got = win.cast(o, d, REACH)
    # The old reference: the same cells as a Dem of their own (own origin and pyramid).
    own = RayCaster.from_dem(tiled.window_dem(*win.window)).cast(o, d, REACH, coherent=False)
    assert np.array_equal(own.offsets, got.offsets)
    np.testing.assert_allclose(own.points, got.points, rtol=0, atol=1e-6)
    with pytest.raises(RaycastError, match="past the window"):
        win.cast(o, d, 3 * REACH)
    with pytest.raises(RaycastError, match="finite"):
        win.cast(o, d)


def test_a_window_of_every_block_is_the_whole_dem(tiled: TiledDem, dem: Dem) -> None:
    nby, nbx = tiled.minmax.shape[:2]
    win = WindowRayCaster.from_blocks(tiled, 0, nby, 0, nbx)
    assert win.window == (0, N, 0, N)
    whole = RayCaster.from_dem(SimpleNamespace(grid=dem.grid, elevation=dem.elevation))
    np.testing.assert_array_equal(win.pyramid.nodes, whole.pyramid.nodes)
    np.testing.assert_array_equal(win.elevation, dem.elevation)


def test_blocks_outside_are_refused(tiled: TiledDem) -> None:
    with pytest.raises(RaycastError, match="outside"):
        WindowRayCaster.from_blocks(tiled, 0, 99, 0, 1)
