"""Tile-parallel viewsheds and coverage on Dask equal the in-memory exact ones, cell for cell.

A 400 x 400 DEM with holes is written with 32-cell blocks; the output tiles (48 cells, so
they straddle DEM blocks) are tasks on a two-worker ``LocalCluster`` in this process.
"""

from __future__ import annotations

import numpy as np
import pytest
from distributed import Client, LocalCluster

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CameraError
from demtrack.core.raycast.tile_cache import slot_bytes
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.tiled_write import synth_cells, write_dem_tiled
from demtrack.core.visibility.tiled_viewshed import coverage_tiles, viewshed_tiles
from demtrack.core.visibility.viewshed import PanTiltLimits, viewshed

N = 400


@pytest.fixture(scope="module")
def dem() -> Dem:
    e = synth_cells(0, N, 0, N, seed=5)[0].copy()
    e[64:70, 100:140] = np.nan
    e[200:210, 250:255] = 320.0  # a tower
    return Dem(GridSpec(-200.0, 200.0, 1.0, N, N), e)


@pytest.fixture(scope="module")
def path(dem: Dem, tmp_path_factory: pytest.TempPathFactory) -> str:
    p = tmp_path_factory.mktemp("vs") / "dem.tif"
    write_dem_tiled(dem, p, tile=32)
    return str(p)


@pytest.fixture(scope="module")
def client() -> Client:
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as lc:
        with Client(lc) as c:
            yield c


def _cameras(dem: Dem) -> list[Camera]:
    intr = Intrinsics(fx=550.0, fy=550.0, cx=319.5, cy=239.5, width=640, height=480)
    cams = []
    for (x, y), az in zip(
        [(-50.0, 30.0), (90.0, -80.0), (0.0, 150.0)], (40.0, 200.0, 170.0), strict=True
    ):
        z = float(dem.sample(np.array([x]), np.array([y]))[0]) + 25.0
        cams.append(Camera.from_azimuth_tilt_roll(intr, np.array([x, y, z]), az, -12.0, 0.0))
    return cams


def test_viewshed_tiles_equal_the_exact_viewshed(dem: Dem, path: str, client: Client) -> None:
    budget = 6 * slot_bytes(32)
    for cam in _cameras(dem):
        for mode in ("fov", "reachable"):
            want = viewshed(dem, cam, mode=mode, max_range_m=300.0, method="exact")
            lazy = viewshed_tiles(
                path, cam, tile=48, memory_budget=budget, mode=mode, max_range_m=300.0
            )
            got = client.compute(lazy).result()
            assert got.dtype == bool and got.shape == dem.grid.shape
            np.testing.assert_array_equal(got, want)
            assert 0 < want.sum() < want.size


def test_coverage_tiles_count_the_cameras(dem: Dem, path: str, client: Client) -> None:
    cams = _cameras(dem)
    limits = PanTiltLimits(-90.0, 90.0, -60.0, 10.0)
    opts = {"mode": "reachable", "max_range_m": 250.0, "limits": limits, "curvature": True}
    want = sum(viewshed(dem, c, method="exact", **opts).astype(np.uint16) for c in cams)
    got = client.compute(coverage_tiles(path, cams, tile=100, **opts)).result()
    np.testing.assert_array_equal(got, want)
    assert got.max() >= 2


def test_bad_options_are_camera_errors(dem: Dem, path: str) -> None:
    cam = _cameras(dem)[0]
    with pytest.raises(CameraError, match="mode"):
        viewshed_tiles(path, cam, mode="everywhere")
    with pytest.raises(CameraError, match="max_range_m"):
        viewshed_tiles(path, cam, max_range_m=-1.0)
    with pytest.raises(CameraError, match="at least one camera"):
        coverage_tiles(path, [])
