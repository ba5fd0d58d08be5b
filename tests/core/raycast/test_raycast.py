from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from demtrack.core.errors import DemError, DemtrackError, RaycastError
from demtrack.core.raycast import _walk_kernels as kernels
from demtrack.core.raycast.cast import (
    BELOW_GROUND,
    HIT,
    MISS,
    OUTSIDE,
    UPWARD,
    RayCaster,
    RayHits,
    RayStatus,
    cast_rays,
)
from demtrack.core.raycast.pyramid import build_pyramid
from demtrack.core.raycast.reference import cast_rays_reference, pyramid_reference
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.surface import bilinear_sample
from demtrack.core.warm import warm_raycast as warm_up


@dataclass(frozen=True)
class FakeDem:
    grid: GridSpec
    elevation: np.ndarray

    def sample(self, x, y):
        gx, gy = self.grid.to_grid(x, y)
        return bilinear_sample(self.elevation, gx, gy)


def make_dem(elev, x_min=0.0, y_max=None, cell=1.0) -> FakeDem:
    elev = np.asarray(elev, dtype=np.float32)
    nrows, ncols = elev.shape
    y_max = nrows * cell if y_max is None else y_max
    return FakeDem(GridSpec(x_min, y_max, cell, nrows, ncols), elev)


def random_dem(rng, holes=True, nrows=None, ncols=None) -> FakeDem:
    nrows = nrows or int(rng.integers(2, 30))
    ncols = ncols or int(rng.integers(2, 30))
    elev = rng.normal(10.0, rng.uniform(0.2, 4.0), (nrows, ncols)).astype(np.float32)
    if holes:
        elev[rng.random((nrows, ncols)) < 0.06] = np.nan
    if np.isnan(elev).all():
        elev[0, 0] = 10.0
    return make_dem(elev, x_min=-40.0, y_max=75.0, cell=float(rng.uniform(0.3, 3.0)))


def random_rays(rng, dem: FakeDem, n: int):
    x0, y0, x1, y1 = dem.grid.bounds
    o = np.column_stack(
        [rng.uniform(x0 - 5, x1 + 5, n), rng.uniform(y0 - 5, y1 + 5, n), rng.uniform(0.0, 30.0, n)]
    )
    d = rng.normal(size=(n, 3))
    d[:, 2] = d[:, 2] * rng.uniform(0.05, 1.0) - rng.uniform(0.0, 0.5)
    return o, d


def brute_force_crossings(dem: FakeDem, o, d, t_max, step=1e-3):
    """Oracle: sample f = z - h densely along the ray and refine sign changes (+ to -)."""
    u = np.asarray(d, float) / np.linalg.norm(d)

    def f(t):
        p = o + np.multiply.outer(t, u)
        return p[..., 2] - dem.sample(p[..., 0], p[..., 1])

    t = np.arange(0.0, t_max, step)
    v = f(t)
    idx = np.flatnonzero((v[:-1] > 0) & (v[1:] < 0))
    return np.array([brentq(f, t[i], t[i + 1], xtol=1e-12) for i in idx])


def assert_same(a: RayHits, b: RayHits, tol=1e-6, check_crossed=True):
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_allclose(a.range_m, b.range_m, rtol=0, atol=tol)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=tol)
    np.testing.assert_array_equal(a.truncated, b.truncated)
    if check_crossed:
        np.testing.assert_array_equal(a.crossed_nodata, b.crossed_nodata)


# ---------------------------------------------------------------------- status & types
def test_status_enum_mirrors_kernel_codes():
    assert [(s.name, int(s)) for s in RayStatus] == [
        ("HIT", kernels.HIT),
        ("MISS", kernels.MISS),
        ("UPWARD", kernels.UPWARD),
        ("BELOW_GROUND", kernels.BELOW_GROUND),
        ("OUTSIDE", kernels.OUTSIDE),
    ]
    assert HIT is RayStatus.HIT and OUTSIDE is RayStatus.OUTSIDE


def test_result_helpers_and_immutability():
    dem = make_dem(np.zeros((5, 5)))
    o = np.array([[2.0, 2.0, 10.0], [2.0, 2.0, -1.0], [50.0, 50.0, 1.0]])
    d = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    h = cast_rays(dem, o, d)
    assert h.n_rays == 3
    np.testing.assert_array_equal(h.status, [HIT, BELOW_GROUND, OUTSIDE])
    np.testing.assert_array_equal(h.counts, [1, 0, 0])
    np.testing.assert_array_equal(h.hit, [True, False, False])
    fp = h.first_points()
    np.testing.assert_allclose(fp[0], [2.0, 2.0, 0.0], atol=1e-12)
    assert np.isnan(fp[1:]).all()
    np.testing.assert_allclose(h.first_range_m(), [10.0, np.nan, np.nan], atol=1e-12)
    r, p = h.hits_of(0)
    np.testing.assert_allclose(r, [10.0])
    assert p.shape == (1, 3)
    assert h.hits_of(-1)[0].shape == (0,)
    with pytest.raises(RaycastError):
        h.hits_of(3)
    assert h.status.dtype == np.int8 and h.offsets.dtype == np.int64
    with pytest.raises(ValueError):
        h.range_m[0] = 1.0


# ---------------------------------------------------------------------- analytic oracles
def test_plane_matches_analytic_intersection():
    rng = np.random.default_rng(0)
    a, b, c = 5.0, 0.1, -0.05
    dem0 = make_dem(np.zeros((25, 30)), x_min=100.0, y_max=300.0, cell=2.0)
    xs, ys = dem0.grid.centres()
    dem = make_dem(a + b * xs + c * ys, x_min=100.0, y_max=300.0, cell=2.0)
    n = 400
    x0, y0, x1, y1 = dem.grid.bounds
    o = np.column_stack(
        [rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(10.0, 40.0, n)]
    )
    d = np.column_stack([rng.normal(size=(n, 2)), -rng.uniform(0.2, 2.0, n)])
    u = d / np.linalg.norm(d, axis=1)[:, None]
    t = (a + b * o[:, 0] + c * o[:, 1] - o[:, 2]) / (u[:, 2] - b * u[:, 0] - c * u[:, 1])
    p = o + t[:, None] * u
    cx0, cy0, cx1, cy1 = dem.grid.centre_bounds
    inside = (p[:, 0] > cx0) & (p[:, 0] < cx1) & (p[:, 1] > cy0) & (p[:, 1] < cy1)
    assert 100 < inside.sum() < n
    h = cast_rays(dem, o, d)
    np.testing.assert_array_equal(h.status == HIT, inside)
    assert (h.counts[inside] == 1).all()
    np.testing.assert_allclose(h.first_range_m()[inside], t[inside], rtol=0, atol=1e-6)
    np.testing.assert_allclose(h.first_points()[inside], p[inside], rtol=0, atol=1e-6)
    assert not h.crossed_nodata.any()


def test_ridge_crossed_twice_gives_two_hits_in_order():
    dem0 = make_dem(np.zeros((20, 120)), cell=1.0)
    xs, _ = dem0.grid.centres()
    dem = make_dem(10.0 * np.exp(-(((xs - 40.0) / 4.0) ** 2)), cell=1.0)
    o = np.array([[2.0, 10.0, 8.0]])
    d = np.array([[1.0, 0.02, -0.1]])
    h = cast_rays(dem, o, d)
    oracle = brute_force_crossings(dem, o[0], d[0], 110.0)
    assert len(oracle) == 2
    assert h.status[0] == HIT and h.counts[0] == 2
    np.testing.assert_allclose(h.range_m, oracle, atol=1e-6)
    assert np.all(np.diff(h.range_m) > 0)
    first = cast_rays(dem, o, d, mode="first")
    np.testing.assert_allclose(first.range_m, oracle[:1], atol=1e-6)


def test_flat_roof_exactly_at_global_max_is_hit():
    elev = np.zeros((12, 12), np.float32)
    elev[4:8, 4:8] = 10.0  # the highest cells of the DEM
    dem = make_dem(elev)
    # Cell (r, c) centre: x = c + 0.5, y = 12 - r - 0.5; the roof spans x, y in [4.5, 7.5].
    o = np.array(
        [
            [6.0, 6.0, 30.0],  # straight down onto the roof
            [5.0, 5.0, 12.0],  # slanted onto the roof
            [6.0, 6.0, 10.0],  # on the roof, looking down: hit at range 0
            [0.6, 6.0, 10.0],
        ]
    )  # level with the roof, over it: touches, never crosses
    d = np.array([[0.0, 0.0, -1.0], [0.5, 0.5, -1.0], [0.3, 0.0, -1.0], [1.0, 0.0, 0.0]])
    h = cast_rays(dem, o, d)
    np.testing.assert_array_equal(h.status, [HIT, HIT, HIT, UPWARD])
    fp = h.first_points()
    np.testing.assert_allclose(fp[:3, 2], 10.0, atol=1e-9)
    np.testing.assert_allclose(fp[0], [6.0, 6.0, 10.0], atol=1e-9)
    np.testing.assert_allclose(h.first_range_m()[:3], [20.0, np.sqrt(1.5) * 2, 0.0], atol=1e-9)
    # The same from slightly lower: a horizontal ray under the roof top runs into its side.
    side = cast_rays(dem, np.array([[0.6, 6.0, 9.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert side.status[0] == HIT
    assert 3.5 < side.points[0, 0] < 4.5


def test_nodata_hole_is_never_hit_and_is_flagged():
    elev = np.full((20, 20), 5.0, np.float32)
    elev[8:12, 8:12] = np.nan  # patches touching these cells are holes
    elev[19, 0] = 8.0  # a mast in a corner: the height range walked is 5..8 m
    dem = make_dem(elev)
    o = np.array(
        [
            [10.0, 10.0, 20.0],  # straight down into the hole
            [3.0, 10.0, 8.0],  # slanted over the hole, lands beyond it
            [3.0, 3.0, 20.0],
        ]
    )  # far from the hole
    d = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, -0.2], [0.0, 0.0, -1.0]])
    for mode in ("all", "first"):
        h = cast_rays(dem, o, d, mode=mode)
        np.testing.assert_array_equal(h.status, [MISS, HIT, HIT])
        np.testing.assert_array_equal(h.crossed_nodata, [True, True, False])
        assert h.counts[0] == 0
        assert np.isfinite(dem.sample(h.points[:, 0], h.points[:, 1])).all()
        np.testing.assert_allclose(h.points[:, 2], 5.0, atol=1e-9)
        assert h.hits_of(1)[1][0, 0] > 12.5  # beyond the hole's far edge
    # Over the hole but above the highest terrain nothing can be missing: no flag.
    h = cast_rays(dem, np.array([[1.0, 10.0, 40.0]]), np.array([[14.0, 0.0, -35.0]]))
    assert h.status[0] == HIT and not h.crossed_nodata[0]
    np.testing.assert_allclose(h.points[0], [15.0, 10.0, 5.0], atol=1e-9)


def test_below_ground_origin_gives_no_hit():
    dem = make_dem(np.full((6, 6), 3.0))
    o = np.array([[2.0, 2.0, 2.0], [2.0, 2.0, 2.0], [2.0, 2.0, -50.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.3, 0.1, 1.0], [1.0, 0.0, 0.0]])
    for mode in ("all", "first"):
        h = cast_rays(dem, o, d, mode=mode)
        assert (h.status == BELOW_GROUND).all()
        assert len(h.range_m) == 0 and np.isnan(h.first_points()).all()


def test_upward_rays():
    xs = np.arange(40, dtype=np.float32) + 0.5
    dem = make_dem(np.tile(xs, (5, 1)))  # z = x: a steady 45 degree slope eastwards
    o = np.array(
        [
            [10.0, 2.5, 50.0],  # above the highest cell (39.5), rising
            [10.0, 2.5, 45.0],  # above it, level
            [1.0, 2.5, 2.0],  # 1 m above the slope, rising slower than it
            [30.0, 2.5, 31.0],
        ]
    )  # above the slope, rising westwards: escapes
    d = np.array([[0.3, 0.0, 1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.5], [-1.0, 0.0, 0.1]])
    h = cast_rays(dem, o, d)
    np.testing.assert_array_equal(h.status, [UPWARD, UPWARD, HIT, MISS])
    np.testing.assert_allclose(h.points[0], [3.0, 2.5, 3.0], atol=1e-9)


def test_rays_outside_the_domain():
    dem = make_dem(np.zeros((10, 10)))  # centres span x, y in [0.5, 9.5]
    o = np.array([[-5.0, 5.0, 3.0], [-5.0, 5.0, 3.0], [-5.0, 5.0, 3.0], [0.2, 5.0, 3.0]])
    d = np.array(
        [
            [-1.0, 0.0, -0.1],  # away from it
            [1.0, 0.0, -0.4],  # towards it: lands inside
            [1.0, 0.0, -0.4],  # towards it, but too short
            [0.0, 0.0, -1.0],
        ]
    )  # straight down in the outer half cell
    h = cast_rays(dem, o, d, max_range=np.array([np.inf, np.inf, 3.0, np.inf]))
    np.testing.assert_array_equal(h.status, [OUTSIDE, HIT, OUTSIDE, OUTSIDE])
    np.testing.assert_allclose(h.points[0], [2.5, 5.0, 0.0], atol=1e-9)


def test_max_range_cuts_hits():
    dem = make_dem(np.zeros((10, 10)))
    o = np.tile([5.0, 5.0, 10.0], (3, 1))
    d = np.tile([0.0, 0.0, -1.0], (3, 1))
    h = cast_rays(dem, o, d, max_range=np.array([9.99, 10.0, 1e9]))
    np.testing.assert_array_equal(h.status, [MISS, HIT, HIT])
    np.testing.assert_allclose(h.range_m, [10.0, 10.0])
    with pytest.raises(RaycastError):
        cast_rays(dem, o, d, max_range=-1.0)


def test_vertical_rays_hit_the_bilinear_surface_exactly():
    rng = np.random.default_rng(1)
    dem = random_dem(rng, holes=False, nrows=9, ncols=13)
    cx0, cy0, cx1, cy1 = dem.grid.centre_bounds
    xc, yc = dem.grid.centres()
    x = np.concatenate([rng.uniform(cx0, cx1, 50), xc.ravel(), [cx0, cx1, cx1]])
    y = np.concatenate([rng.uniform(cy0, cy1, 50), yc.ravel(), [cy0, cy1, cy0]])
    o = np.column_stack([x, y, np.full(len(x), 100.0)])
    d = np.tile([0.0, 0.0, -1.0], (len(x), 1))
    h = cast_rays(dem, o, d)
    # On the hull's edge, rounding of x, y to grid coordinates decides; it decides the
    # same way for the surface sampler.
    z = dem.sample(x, y)
    on = np.isfinite(z)
    assert on.sum() > 140
    np.testing.assert_array_equal(h.status, np.where(on, HIT, OUTSIDE))
    assert (h.counts == on).all()
    np.testing.assert_allclose(h.points[:, 2], z[on], rtol=0, atol=1e-9)
    np.testing.assert_allclose(h.range_m, 100.0 - z[on], rtol=0, atol=1e-9)


def test_grid_line_and_vertex_rays_match_reference_and_brute_force():
    rng = np.random.default_rng(2)
    dem = random_dem(rng, holes=False, nrows=15, ncols=15)
    dem = make_dem(dem.elevation, cell=1.0)
    xc, yc = dem.grid.centres()
    o, d = [], []
    for k in range(1, 14):
        o += [
            [xc[0, k], yc[0, 0] + 3.0, 25.0],  # along a column of centres (x = const)
            [xc[0, 0] - 2.0, yc[k, 0], 25.0],  # along a row of centres (y = const)
            [xc[0, 0] - 1.0, yc[0, 0] + 1.0, 30.0 - k],
        ]  # diagonal through every vertex
        d += [[0.0, -1.0, -1.2], [1.0, 0.0, -1.2], [1.0, -1.0, -1.5]]
    o, d = np.array(o), np.array(d)
    h = cast_rays(dem, o, d)
    assert_same(h, cast_rays_reference(dem, o, d))
    assert (h.status == HIT).mean() > 0.8
    for i in range(0, len(o), 4):
        oracle = brute_force_crossings(dem, o[i], d[i], 40.0)
        np.testing.assert_allclose(h.hits_of(i)[0], oracle, atol=1e-6)


# ---------------------------------------------------------------------- reference twin
@pytest.mark.parametrize("seed", range(12))
def test_matches_reference_on_random_terrain(seed):
    rng = np.random.default_rng(seed)
    dem = random_dem(rng, holes=seed % 2 == 0)
    o, d = random_rays(rng, dem, 150)
    for mode in ("all", "first"):
        a = cast_rays(dem, o, d, mode=mode, max_hits=6)
        b = cast_rays_reference(dem, o, d, mode=mode, max_hits=6)
        assert_same(a, b)
    # Also with a per-ray max_range.
    rng_m = rng.uniform(0.0, 60.0, len(o))
    assert_same(cast_rays(dem, o, d, rng_m), cast_rays_reference(dem, o, d, rng_m))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-3, 10.0))
def test_property_matches_reference_and_lies_on_surface(seed, scale):
    rng = np.random.default_rng(seed)
    dem = random_dem(rng)
    o, d = random_rays(rng, dem, 40)
    h = cast_rays(dem, o, d * scale)  # direction length must not matter
    assert_same(h, cast_rays_reference(dem, o, d))
    # Every hit is on the surface, never in a hole, and ranges grow along each ray.
    np.testing.assert_allclose(
        h.points[:, 2], dem.sample(h.points[:, 0], h.points[:, 1]), atol=1e-6
    )
    assert (np.diff(h.range_m)[np.diff(np.repeat(np.arange(40), h.counts)) == 0] > 0).all()
    assert ((h.status == HIT) == (h.counts > 0)).all()
    first = cast_rays(dem, o, d, mode="first")
    np.testing.assert_allclose(first.first_points(), h.first_points(), atol=1e-9)
    np.testing.assert_array_equal(first.status, h.status)
    assert (first.crossed_nodata <= h.crossed_nodata).all()


@pytest.mark.parametrize("seed", range(6))
def test_shared_origin_batches_match_reference(seed):
    # Camera-like batches (one origin, neighbouring directions), the case any packet or
    # reordering scheme would exploit: holes, many crossings and re-walks included.
    rng = np.random.default_rng(100 + seed)
    dem = random_dem(rng, holes=seed % 2 == 0, nrows=40, ncols=40)
    x0, y0, x1, y1 = dem.grid.bounds
    origins, dirs = [], []
    for _ in range(4):
        centre = [rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(12.0, 25.0)]
        az = rng.uniform(0, 2 * np.pi)
        a = az + np.linspace(-0.4, 0.4, 32)[None, :] + np.zeros((6, 1))
        dip = np.linspace(-0.05, -1.2, 6)[:, None] + np.zeros((1, 32))
        d = np.column_stack(
            [
                np.sin(a.ravel()) * np.cos(dip.ravel()),
                np.cos(a.ravel()) * np.cos(dip.ravel()),
                np.sin(dip.ravel()),
            ]
        )
        origins.append(np.tile(centre, (len(d), 1)))
        dirs.append(d)
    o, d = np.vstack(origins), np.vstack(dirs)
    for mode, max_hits in (("all", 256), ("all", 5), ("first", 1)):
        a = cast_rays(dem, o, d, mode=mode, max_hits=max_hits)
        b = cast_rays_reference(dem, o, d, mode=mode, max_hits=max_hits)
        assert_same(a, b)
    # The same rays cast one by one give bit-identical answers.
    caster = RayCaster.from_dem(dem)
    packed = caster.cast(o, d)
    single = [caster.cast(o[i : i + 1], d[i : i + 1]) for i in range(0, len(o), 7)]
    for k, i in enumerate(range(0, len(o), 7)):
        np.testing.assert_array_equal(packed.hits_of(i)[0], single[k].range_m)
        assert packed.crossed_nodata[i] == single[k].crossed_nodata[0]


def test_many_crossings_refill_and_truncation():
    zig = np.tile(np.array([0.0, 10.0], np.float32), 20)
    dem = make_dem(np.vstack([zig, zig, zig]))
    o = np.array([[0.5, 1.5, 5.0]])
    d = np.array([[1.0, 0.0, 0.0]])  # level at 5 m over a zig-zag: one crossing per tooth
    full = cast_rays(dem, o, d)
    # Rising through 5 m halfway between a 0 m and a 10 m centre: x = 1, 3, ..., 39.
    assert full.counts[0] == 20 and not full.truncated[0]
    np.testing.assert_allclose(full.points[:, 0], 2.0 * np.arange(20) + 1.0, atol=1e-9)
    assert_same(full, cast_rays_reference(dem, o, d))
    cut = cast_rays(dem, o, d, max_hits=3)
    assert cut.truncated[0] and cut.counts[0] == 3
    np.testing.assert_allclose(cut.range_m, full.range_m[:3])
    assert_same(cut, cast_rays_reference(dem, o, d, max_hits=3))


def test_pyramid_matches_reference():
    rng = np.random.default_rng(3)
    for _ in range(10):
        nr, nc = rng.integers(2, 40, 2)
        e = rng.normal(size=(nr, nc)).astype(np.float32)
        e[rng.random((nr, nc)) < 0.05] = np.nan
        e[0, 0] = 1.0
        p = build_pyramid(e)
        ref = pyramid_reference(e)
        assert p.n_levels == len(ref) - 1
        for k in range(1, p.n_levels + 1):
            np.testing.assert_array_equal(p.level(k), ref[k])
        assert p.z_min == np.nanmin(e) and p.z_max == np.nanmax(e)
        assert p.level(p.n_levels).shape == (1, 1, 2)
    with pytest.raises(DemError):
        build_pyramid(np.full((3, 3), np.nan, np.float32))
    with pytest.raises(DemError):
        build_pyramid(np.zeros((1, 5), np.float32))


@pytest.mark.parametrize("use_kernel", [True, False])
def test_pyramid_root_tells_whether_the_dem_has_holes(use_kernel):
    """``has_holes`` (the walks skip the NaN tests without holes) sees any single hole,
    wherever it is, corners and last row and column included, from either builder."""
    rng = np.random.default_rng(5)
    for nr, nc in [(2, 2), (2, 7), (5, 3), (17, 23), (64, 65)]:
        e = rng.normal(size=(nr, nc)).astype(np.float32)
        p = build_pyramid(e, use_kernel=use_kernel)
        assert not kernels.has_holes(p.nodes, p.level_offsets)
        for r, c in [(0, 0), (nr - 1, nc - 1), (nr - 1, 0), (0, nc - 1), (nr // 2, nc // 2)]:
            h = e.copy()
            h[r, c] = np.nan
            p = build_pyramid(h, use_kernel=use_kernel)
            assert kernels.has_holes(p.nodes, p.level_offsets), (nr, nc, r, c)


# ---------------------------------------------------------------------- API behaviour
def test_thread_count_does_not_change_answers():
    rng = np.random.default_rng(4)
    dem = random_dem(rng)
    o, d = random_rays(rng, dem, 3000)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = cast_rays(dem, o, d)
    finally:
        numba.set_num_threads(before)
    assert_same(one, cast_rays(dem, o, d), tol=0.0)


def test_ray_caster_reuse_and_real_dem():
    from demtrack.core.terrain.dem import Dem

    rng = np.random.default_rng(5)
    fake = random_dem(rng)
    dem = Dem(fake.grid, fake.elevation)
    o, d = random_rays(rng, fake, 200)
    caster = RayCaster.from_dem(dem)
    assert_same(caster.cast(o, d), cast_rays(fake, o, d), tol=0.0)
    assert_same(cast_rays(caster, o, d, mode="first"), cast_rays(dem, o, d, mode="first"))
    h = caster.cast(o, d)
    np.testing.assert_allclose(
        h.points[:, 2], dem.sample(h.points[:, 0], h.points[:, 1]), atol=1e-6
    )


def test_empty_batch():
    h = cast_rays(make_dem(np.zeros((3, 3))), np.empty((0, 3)), np.empty((0, 3)))
    assert h.n_rays == 0 and h.offsets.tolist() == [0] and h.points.shape == (0, 3)


@pytest.mark.parametrize(
    "origins, directions, kwargs",
    [
        (np.zeros((2, 2)), np.ones((2, 2)), {}),
        (np.zeros((2, 3)), np.ones((3, 3)), {}),
        (np.zeros((1, 3)), np.zeros((1, 3)), {}),
        (np.full((1, 3), np.nan), np.ones((1, 3)), {}),
        (np.zeros((1, 3)), np.full((1, 3), np.inf), {}),
        (np.zeros((1, 3)), np.ones((1, 3)), {"mode": "nearest"}),
        (np.zeros((1, 3)), np.ones((1, 3)), {"max_hits": 0}),
        (np.zeros((1, 3)), np.ones((1, 3)), {"max_range": np.nan}),
        (np.zeros((2, 3)), np.ones((2, 3)), {"max_range": np.ones(3)}),
    ],
)
def test_bad_rays_are_rejected(origins, directions, kwargs):
    with pytest.raises(RaycastError) as info:
        cast_rays(make_dem(np.zeros((3, 3))), origins, directions, **kwargs)
    assert isinstance(info.value, DemtrackError) and isinstance(info.value, ValueError)


def test_bad_dems_are_rejected():
    with pytest.raises(DemError):
        cast_rays(make_dem(np.zeros((1, 4))), np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(DemError):
        cast_rays(make_dem(np.full((3, 3), np.nan)), np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(DemError):
        cast_rays(object(), np.zeros((1, 3)), np.ones((1, 3)))
    bad = FakeDem(GridSpec(0.0, 3.0, 1.0, 3, 3), np.zeros((3, 4), np.float32))
    with pytest.raises(DemError):
        cast_rays(bad, np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(DemError):
        cast_rays(make_dem(np.full((3, 3), np.inf)), np.zeros((1, 3)), np.ones((1, 3)))


def test_caster_is_not_fooled_by_later_edits_of_the_grid():
    elev = np.zeros((4, 4), np.float32)
    caster = RayCaster.from_dem(make_dem(elev))
    elev[:] = 100.0  # the caller's array changes; the caster kept its own copy
    h = caster.cast(np.array([[2.0, 2.0, 10.0]]), np.array([[0.0, 0.0, -1.0]]))
    np.testing.assert_allclose(h.points[0, 2], 0.0)


def test_warm_up_compiles_without_error():
    warm_up()


@pytest.mark.skipif(importlib.util.find_spec("open3d") is None, reason="open3d not installed")
def test_benchmark_smoke(capsys):
    from demtrack.bench.raycast import main

    before = numba.get_num_threads()
    try:
        assert main(["--size", "64", "--rays", "2000", "--repeat", "1", "--threads", "1"]) == 0
    finally:
        numba.set_num_threads(before)
    out = capsys.readouterr().out
    assert "camera rays, first hit" in out and "Open3D/Embree" in out
    pyramid_only = [ln for ln in out.splitlines() if "(pyramid only) rays" in ln]
    assert len(pyramid_only) == 2 and all(ln.endswith("(comparison)") for ln in pyramid_only)
