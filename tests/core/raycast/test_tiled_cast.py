"""The tiled ray caster against the in-memory one (bit for bit) and the numpy twin.

Seams are where a tiled walk goes wrong: rays along block seams (``kx == 0`` exactly on a
block's first column), through block corners, grazing a flat roof that straddles a seam,
over holes on a seam, plus a pool of a few blocks that must evict. The oracle is
``RayCaster``'s pyramid walk (``coherent=False``) on the same cells in memory, and
``core.raycast.reference`` for a few hundred rays.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from raycast_checks import assert_identical_hits

from demtrack.core.errors import RaycastError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.raycast.reference import cast_rays_reference
from demtrack.core.raycast.tile_cache import slot_bytes
from demtrack.core.raycast.tiled_cast import TiledRayCaster
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.tiled_write import synth_cells, write_dem_tiled

TILE = 64
N = 1000


def _terrain(n: int = N, holes: bool = True) -> Dem:
    """Synthetic hills with flat roofs and holes placed on block seams and corners."""
    e = synth_cells(0, n, 0, n, seed=3)[0].copy()
    e[100:140, 120:200] = 290.0  # a roof across the seam at column 128
    e[250:300, 250:260] = 300.0  # a roof across the block corner (256, 256)
    if n < N:  # for 16-cell tiles: a hole on a seam row and one at a block corner
        e[32:34, 10:20] = np.nan
        e[47:49, 47:49] = np.nan
    elif holes:
        e[192:195, 60:70] = np.nan  # holes on the seam row 192
        e[500:510, 384] = np.nan  # and on the seam column 384
        e[639:641, 639:641] = np.nan  # at a block corner (640, 640)
    grid = GridSpec(-0.5 * n, 0.5 * n, 1.0, n, n)
    return Dem(grid, e)


@pytest.fixture(scope="module")
def dem() -> Dem:
    return _terrain()


@pytest.fixture(scope="module")
def tiled(dem: Dem, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("tiled") / "dem.tif"
    write_dem_tiled(dem, path, tile=TILE)
    return path


@pytest.fixture(scope="module")
def caster(dem: Dem) -> RayCaster:
    return RayCaster.from_dem(SimpleNamespace(grid=dem.grid, elevation=dem.elevation))


def _tiled(path: Path, blocks: int = 6) -> TiledRayCaster:
    return TiledRayCaster.open(str(path), blocks * slot_bytes(TILE))


def _random_rays(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    o = np.c_[rng.uniform(-520, 520, n), rng.uniform(-520, 520, n), rng.uniform(150, 420, n)]
    d = np.c_[rng.normal(size=n), rng.normal(size=n), -np.abs(rng.normal(size=n)) * 0.4]
    return o, d


def _seam_rays() -> tuple[np.ndarray, np.ndarray]:
    """Rays along seams, through block corners, grazing roofs and along grid lines."""
    g = _terrain().grid
    o: list[list[float]] = []
    d: list[list[float]] = []
    for k in (64, 128, 192, 384, 640, 960):
        x, y = g.from_grid(np.float64(k), np.float64(k))
        for dz in (-0.02, -0.1, -0.5):
            o += [[x, 480.0, 330.0], [-480.0, y, 330.0], [x, y, 330.0], [x + 0.5, y, 330.0]]
            d += [[0.0, -1.0, dz], [1.0, 0.0, dz], [1.0, -1.0, dz], [0.0, 1.0, dz]]
        # Grazing the roofs at exactly their height, and level rays at the global max.
        o += [[x, 480.0, 290.0], [-480.0, y, 300.0]]
        d += [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]
    # Through the corner (640, 640) of the hole, diagonally both ways.
    cx, cy = g.from_grid(np.float64(640), np.float64(640))
    for sx, sy in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        o.append([cx - 40 * sx, cy - 40 * sy, 320.0])
        d.append([float(sx), float(sy), -1.2])
    return np.asarray(o), np.asarray(d)


def test_random_rays_are_bit_identical(tiled: Path, caster: RayCaster) -> None:
    o, d = _random_rays(3000, 0)
    tc = _tiled(tiled)
    assert_identical_hits(tc.cast(o, d), caster.cast(o, d, coherent=False))
    assert tc.stats.loads > 0 and tc.stats.evictions > 0


def test_seam_corner_and_grazing_rays_are_bit_identical(tiled: Path, caster: RayCaster) -> None:
    o, d = _seam_rays()
    tc = _tiled(tiled, blocks=3)
    got = tc.cast(o, d)
    want = caster.cast(o, d, coherent=False)
    assert_identical_hits(got, want)
    assert want.hit.sum() > len(o) // 4  # many of the rays do meet the terrain
    assert want.crossed_nodata.any()  # and some pass over the holes on seams


def test_camera_fan_first_mode_and_truncation(tiled: Path, caster: RayCaster) -> None:
    """A camera's pixels (one origin), mode first and a small max_hits."""
    az = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    el = np.linspace(-0.6, -0.02, 25)
    a, e = np.meshgrid(az, el)
    d = np.c_[(np.cos(e) * np.cos(a)).ravel(), (np.cos(e) * np.sin(a)).ravel(), np.sin(e).ravel()]
    o = np.tile([10.0, -20.0, 330.0], (len(d), 1))
    tc = _tiled(tiled, blocks=4)
    for mode, max_hits in (("all", 256), ("first", 1), ("all", 2)):
        want = caster.cast(o, d, 900.0, mode=mode, max_hits=max_hits, coherent=False)
        assert_identical_hits(tc.cast(o, d, 900.0, mode=mode, max_hits=max_hits), want)
    assert caster.cast(o, d, 900.0, max_hits=2, coherent=False).truncated.any()


def test_angular_index_agrees_to_rounding(tiled: Path, caster: RayCaster) -> None:
    """The in-memory camera path (angular index) gives the same hits to well under 1e-9 m."""
    az = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    d = np.c_[np.cos(az), np.sin(az), np.full_like(az, -0.2)]
    o = np.tile([0.0, 0.0, 320.0], (len(d), 1))
    got = _tiled(tiled).cast(o, d)
    want = caster.cast(o, d, coherent=True)
    np.testing.assert_array_equal(got.offsets, want.offsets)
    np.testing.assert_allclose(got.range_m, want.range_m, rtol=0, atol=1e-9)


def test_matches_the_numpy_reference(tiled: Path, dem: Dem) -> None:
    o, d = _random_rays(150, 1)
    got = _tiled(tiled, blocks=2).cast(o, d)
    want = cast_rays_reference(dem, o, d)
    np.testing.assert_array_equal(got.status, want.status)
    np.testing.assert_array_equal(got.offsets, want.offsets)
    np.testing.assert_allclose(got.range_m, want.range_m, rtol=0, atol=1e-6)


def test_pool_never_exceeds_its_budget_and_reuses_blocks(tiled: Path) -> None:
    budget = 3 * slot_bytes(TILE) + 100
    tc = TiledRayCaster.open(str(tiled), budget)
    o, d = _random_rays(2000, 2)
    tc.cast(o, d)
    c = tc.cache
    assert c.n_slots == 3 and c.resident_bytes <= budget
    assert c.pool_elev.nbytes + c.pool_nodes.nbytes <= budget
    s = tc.stats
    assert s.evictions == s.loads - 3 and s.hits > 0 and s.misses > 0
    # The same rays again: every block they need is read again or still resident.
    before = s.loads
    tc.cast(o[:1], d[:1])
    assert tc.stats.loads - before <= 2


@pytest.mark.parametrize("tile", [16, 2048])
def test_small_tiles_and_a_tile_larger_than_the_dem(tmp_path: Path, tile: int) -> None:
    """Coarse levels starting at level 4 (the set-up's node), or none at all."""
    dem = _terrain(200)
    path = tmp_path / "t.tif"
    write_dem_tiled(dem, path, tile=tile)
    tc = TiledRayCaster.open(str(path), 4 * slot_bytes(tile))
    o, d = _random_rays(800, 4)
    o[:, :2] *= 0.2
    want = RayCaster.from_dem(SimpleNamespace(grid=dem.grid, elevation=dem.elevation))
    assert_identical_hits(tc.cast(o, d), want.cast(o, d, coherent=False))


def test_bad_budget_and_rays_are_one_line_errors(tiled: Path) -> None:
    with pytest.raises(RaycastError, match="below one 64 x 64 tile"):
        TiledRayCaster.open(str(tiled), 1000)
    tc = _tiled(tiled)
    with pytest.raises(RaycastError, match="shape"):
        tc.cast(np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(RaycastError, match="mode"):
        tc.cast(np.zeros((1, 3)), np.ones((1, 3)), mode="most")  # type: ignore[arg-type]


def test_a_dem_without_holes_reads_no_halo(tmp_path: Path) -> None:
    """Without holes only the next row and column are read, from resident neighbours."""
    dem = _terrain(holes=False)
    path = tmp_path / "t.tif"
    write_dem_tiled(dem, path, tile=TILE)
    tc = _tiled(path, blocks=40)
    o, d = _random_rays(2500, 5)
    want = RayCaster.from_dem(SimpleNamespace(grid=dem.grid, elevation=dem.elevation))
    assert_identical_hits(tc.cast(o, d), want.cast(o, d, coherent=False))
    assert not tc.dem.holes and tc.stats.loads > 40  # evictions, refills of edges
