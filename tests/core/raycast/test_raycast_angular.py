"""Origin-specific angular index (core.raycast.angular_index): conservative, exact, cached."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import RaycastError
from demtrack.core.raycast import _angular_kernels as ak
from demtrack.core.raycast.angular_index import (
    AngularCache,
    _cone,
    build_angular_index,
    needed_azimuth_bins,
    tree_levels,
)
from demtrack.core.raycast.cast import (
    BELOW_GROUND,
    HEIGHT_MARGIN_M,
    MIN_COHERENT_RUN,
    RayCaster,
    RayHits,
)
from demtrack.core.raycast.reference import (
    angular_leaves_reference,
    cast_rays_reference,
    next_candidate_reference,
    pseudo_angle_reference,
)
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.surface import bilinear_sample


@dataclass(frozen=True)
class FakeDem:
    grid: GridSpec
    elevation: np.ndarray


def random_dem(rng, holes=True, nrows=None, ncols=None) -> FakeDem:
    nrows = nrows or int(rng.integers(3, 30))
    ncols = ncols or int(rng.integers(3, 30))
    elev = rng.normal(10.0, rng.uniform(0.2, 4.0), (nrows, ncols)).astype(np.float32)
    if holes:
        elev[rng.random((nrows, ncols)) < 0.06] = np.nan
    elev[0, 0] = 10.0
    cell = float(rng.uniform(0.3, 3.0))
    return FakeDem(GridSpec(-40.0, 75.0, cell, nrows, ncols), elev)


def camera_batch(rng, dem: FakeDem, n_cams=3, inside=True, n_az=24, n_el=8):
    """Rays of pinhole-like fans from a few origins (some may point up or miss)."""
    x0, y0, x1, y1 = dem.grid.bounds
    pad = 0.0 if inside else 0.5 * (x1 - x0)
    origins, dirs = [], []
    for _ in range(n_cams):
        c = [rng.uniform(x0 - pad, x1 + pad), rng.uniform(y0 - pad, y1 + pad)]
        c.append(float(rng.uniform(11.0, 30.0)))
        az = rng.uniform(0, 2 * np.pi) + np.linspace(-0.7, 0.7, n_az)
        el = np.linspace(0.15, -1.3, n_el)
        a, e = np.meshgrid(az, el)
        d = np.column_stack(
            [
                np.sin(a.ravel()) * np.cos(e.ravel()),
                np.cos(a.ravel()) * np.cos(e.ravel()),
                np.sin(e.ravel()),
            ]
        )
        origins.append(np.tile(c, (len(d), 1)))
        dirs.append(d)
    return np.vstack(origins), np.vstack(dirs)


def assert_same(a: RayHits, b: RayHits, tol=1e-9):
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_allclose(a.range_m, b.range_m, rtol=0, atol=tol)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=tol)
    np.testing.assert_array_equal(a.truncated, b.truncated)
    np.testing.assert_array_equal(a.crossed_nodata, b.crossed_nodata)


def full_index(dem: FakeDem, origin, n_az=64, d_rho=1.0):
    caster = RayCaster.from_dem(dem)
    g = caster.grid
    return build_angular_index(
        caster.elevation,
        (g.x_min, g.y_max, g.cell_m),
        np.asarray(origin, float),
        np.ones(n_az, bool),
        margin_m=HEIGHT_MARGIN_M,
        n_az=n_az,
        d_rho=d_rho,
    )


# ---------------------------------------------------------------------- structure
def test_pseudo_angle_is_increasing_and_matches_twin():
    theta = np.linspace(-np.pi, np.pi, 2001)[:-1]
    dx, dy = np.cos(theta), np.sin(theta)
    p = pseudo_angle_reference(dx, dy)
    k = np.array([ak.pseudo_angle(a, b) for a, b in zip(dx, dy, strict=True)])
    np.testing.assert_array_equal(k, p)
    # Increasing with atan2 from -pi (p = 2) round to pi, with its one cut at +x (p = 0).
    order = np.argsort(np.mod(theta, 2 * np.pi))
    assert np.all(np.diff(p[order]) > 0)
    assert p.min() >= 0 and p.max() < 4
    # Opposite directions differ by exactly 2.
    np.testing.assert_allclose(np.mod(p - pseudo_angle_reference(-dx, -dy), 4.0), 2.0, atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_leaves_match_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    dem = random_dem(rng, holes=seed % 2 == 0)
    x0, y0, x1, y1 = dem.grid.bounds
    pad = 0.0 if seed < 4 else 20.0
    origin = [rng.uniform(x0 - pad, x1 + pad), rng.uniform(y0 - pad, y1 + pad), rng.uniform(5, 25)]
    ix = full_index(
        dem, origin, n_az=int(rng.choice([16, 64, 256])), d_rho=float(rng.choice([0.5, 1.0, 2.0]))
    )
    ref = angular_leaves_reference(
        dem.elevation, ix.gxo, ix.gyo, origin[2], ix.n_az, ix.d_rho, ix.n_range_bins
    )
    got = np.stack([ix.leaves(a) for a in range(ix.n_az)])
    np.testing.assert_array_equal(got, ref)


def test_leaves_built_for_a_sector_match_the_full_index():
    # Building only a camera's sector scans only the patches of its cone: same bins.
    rng = np.random.default_rng(11)
    dem = random_dem(rng, nrows=40, ncols=40)
    caster = RayCaster.from_dem(dem)
    o, d = camera_batch(rng, dem, n_cams=6)
    for k in range(6):
        rows = slice(k * 192, (k + 1) * 192)
        ix = caster.prepare_origin(o[rows][0], d[rows])
        assert 0 < ix.n_slots < ix.n_az
        full = full_index(dem, o[rows][0], n_az=ix.n_az, d_rho=ix.d_rho)
        for a in np.flatnonzero(ix.slot_of_az >= 0):
            np.testing.assert_array_equal(ix.leaves(a), full.leaves(a))


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_bins_bound_every_surface_point(seed):
    # The invariant exactness rests on: every point of the surface lies inside the angle
    # interval of its polar bin.
    rng = np.random.default_rng(seed)
    dem = random_dem(rng)
    x0, y0, x1, y1 = dem.grid.bounds
    origin = [rng.uniform(x0 - 5, x1 + 5), rng.uniform(y0 - 5, y1 + 5), rng.uniform(0, 25)]
    ix = full_index(dem, origin, n_az=int(rng.choice([8, 64, 512])))
    nr, nc = dem.elevation.shape
    gx = rng.uniform(0, nc - 1, 4000)
    gy = rng.uniform(0, nr - 1, 4000)
    z = bilinear_sample(dem.elevation, gx, gy)
    ok = np.isfinite(z)
    gx, gy, z = gx[ok], gy[ok], z[ok]
    dx, dy = gx - ix.gxo, gy - ix.gyo
    rho = np.hypot(dx, dy)
    keep = rho > 1e-6
    a = np.minimum((pseudo_angle_reference(dx, dy) * ix.n_az / 4).astype(int), ix.n_az - 1)[keep]
    b = (rho / ix.d_rho).astype(int)[keep]
    ang = ((z - origin[2]) / rho)[keep]
    leaves = np.stack([ix.leaves(k) for k in range(ix.n_az)])
    assert np.all(leaves[a, b, 0] >= ang)
    assert np.all(leaves[a, b, 1] <= ang)


def test_tree_levels_and_query_match_linear_scan():
    rng = np.random.default_rng(2)
    dem = random_dem(rng, nrows=30, ncols=30)
    ix = full_index(dem, [-30.0, 60.0, 18.0], n_az=32)
    off, size = tree_levels(ix.n_range_bins)
    np.testing.assert_array_equal(off, ix.t_off)
    assert size[-1] == 1
    for a in np.flatnonzero(ix.slot_of_az >= 0):
        tr = ix.tree[ix.slot_of_az[a]]
        for lv in range(1, len(size)):
            child = tr[off[lv - 1] : off[lv - 1] + size[lv - 1]]
            pad = np.concatenate([child, child[-1:]]) if len(child) % 2 else child
            node = tr[off[lv] : off[lv] + size[lv]]
            np.testing.assert_array_equal(node[:, 0], pad[:, 0].reshape(-1, 2).max(axis=1))
            np.testing.assert_array_equal(node[:, 1], pad[:, 1].reshape(-1, 2).min(axis=1))
        leaves = ix.leaves(a)
        finite = leaves[np.isfinite(leaves)]
        for _ in range(40):
            b = int(rng.integers(0, ix.n_range_bins))
            b_end = int(rng.integers(b, ix.n_range_bins))
            s = (
                float(rng.choice(finite))
                if len(finite) and rng.random() < 0.5
                else rng.normal(0, 2)
            )
            assert ak.next_candidate(tr, ix.t_off, ix.t_size, b, b_end, s) == (
                next_candidate_reference(leaves, b, b_end, s)
            )
        # The start table: nothing before start[q] reaches the class's lower edge; the
        # end: the last leaf whose bounds meet the class's slopes.
        n_q = ix.start.shape[1]
        for q in range(0, n_q, 37):
            edge = ak.slope_class_edge(q, n_q, ix.s_unit)
            top = ak.slope_class_top(q, n_q, ix.s_unit)
            st_q, end_q = ix.start[ix.slot_of_az[a], q]
            assert np.all(leaves[:st_q, 0] < edge)
            assert st_q == ix.n_range_bins or leaves[st_q, 0] >= edge
            meets = np.flatnonzero((leaves[:, 0] >= edge) & (leaves[:, 1] <= top))
            assert end_q == (meets[-1] if len(meets) else -1)
    for s in np.concatenate([rng.normal(0, 3, 200), rng.normal(0, 300, 50), [0.0]]):
        q = ak.slope_class(s, 1024, ix.s_unit)
        assert (
            ak.slope_class_edge(q, 1024, ix.s_unit) <= s <= ak.slope_class_top(q, 1024, ix.s_unit)
        )


# ---------------------------------------------------------------------- exact casting
@pytest.mark.parametrize("seed", range(10))
def test_coherent_cast_matches_pyramid_walk_and_reference(seed):
    rng = np.random.default_rng(300 + seed)
    dem = random_dem(
        rng, holes=seed % 2 == 0, nrows=int(rng.integers(5, 40)), ncols=int(rng.integers(5, 40))
    )
    o, d = camera_batch(rng, dem, inside=seed < 6)
    caster = RayCaster.from_dem(dem)
    max_range = rng.uniform(5.0, 80.0, len(o)) if seed % 3 == 0 else np.inf
    for mode, max_hits in (("first", 1), ("all", 256), ("all", 2)):
        a = caster.cast(o, d, max_range, mode=mode, max_hits=max_hits, coherent=True)
        b = caster.cast(o, d, max_range, mode=mode, max_hits=max_hits, coherent=False)
        assert_same(a, b)
        r = cast_rays_reference(dem, o, d, max_range, mode=mode, max_hits=max_hits)
        assert_same(a, r, tol=1e-6)
    assert len(caster.angular) == 3


def test_coherent_cast_on_a_ridge_field_with_many_crossings():
    # Near-level rays over a corrugated surface: many candidate runs, hits and re-walks.
    x = np.arange(90)
    elev = 5.0 + 3.0 * np.sin(x / 1.3)[None, :] + 0.5 * np.cos(x / 3.1)[:, None]
    elev = elev.astype(np.float32)
    elev[20:24, 30:33] = np.nan
    dem = FakeDem(GridSpec(0.0, 90.0, 1.0, 90, 90), elev)
    n = 400
    az = np.linspace(0.1, 6.2, n)
    el = np.linspace(0.0, -0.05, n)
    d = np.column_stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    o = np.tile([45.2, 44.7, 6.5], (n, 1))
    caster = RayCaster.from_dem(dem)
    for mode in ("first", "all"):
        a = caster.cast(o, d, mode=mode, coherent=True)
        assert_same(a, caster.cast(o, d, mode=mode, coherent=False))
        assert_same(a, cast_rays_reference(dem, o, d, mode=mode), tol=1e-6)
    assert a.counts.max() > 4  # the re-walk of rays with many hits is exercised
    assert a.crossed_nodata.any()


def test_rays_with_more_hits_than_the_first_pass_keeps_are_rewalked_through_the_index():
    # Near-level rays along a long corrugated strip cross it dozens of times: more than
    # the first pass of a coherent batch keeps, so they are re-walked (angular re-walk).
    x = np.arange(240)
    elev = 5.0 + 3.0 * np.sin(x / 1.3)[None, :] + 0.3 * np.cos(np.arange(12) / 2.0)[:, None]
    elev = elev.astype(np.float32)
    elev[4:7, 40:43] = np.nan
    dem = FakeDem(GridSpec(0.0, 12.0, 1.0, 12, 240), elev)
    n = 120
    az = np.radians(np.linspace(89.0, 91.0, n))
    el = np.linspace(0.0, -0.02, n)
    d = np.column_stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    o = np.tile([4.6, 6.1, 6.5], (n, 1))
    caster = RayCaster.from_dem(dem)
    for max_hits in (256, 11):
        a = caster.cast(o, d, mode="all", max_hits=max_hits, coherent=True)
        assert_same(a, caster.cast(o, d, mode="all", max_hits=max_hits, coherent=False))
        assert_same(a, cast_rays_reference(dem, o, d, mode="all", max_hits=max_hits), tol=1e-6)
        assert a.counts.max() > 8
    assert a.truncated.any() and a.crossed_nodata.any()


def test_a_run_from_under_the_surface_is_below_ground():
    # The per-run set-up decides "below ground" once for the origin, as _prepare does per ray.
    rng = np.random.default_rng(11)
    dem = random_dem(rng, holes=False, nrows=20, ncols=20)
    caster = RayCaster.from_dem(dem)
    o, d = camera_batch(rng, dem, n_cams=1)
    x, y = o[0, 0], o[0, 1]
    for dz in (-0.5, 0.5):
        gx, gy = dem.grid.to_grid(np.array([x]), np.array([y]))
        z = float(bilinear_sample(dem.elevation, gx, gy)[0])
        oz = np.tile([x, y, z + dz], (len(o), 1))
        a = caster.cast(oz, d, coherent=True)
        assert_same(a, caster.cast(oz, d, coherent=False))
        assert_same(a, cast_rays_reference(dem, oz, d), tol=1e-6)
        assert (a.status == BELOW_GROUND).any() == (dz < 0)


def test_a_cached_index_missing_bins_casts_exactly_and_is_extended_after():
    rng = np.random.default_rng(12)
    dem = random_dem(rng, nrows=25, ncols=25)
    caster = RayCaster.from_dem(dem)
    o, d = camera_batch(rng, dem, n_cams=1, n_az=60)
    third = d.reshape(8, 60, 3)[:, :20].reshape(-1, 3)  # a third of the azimuths
    part = caster.prepare_origin(o[0], third)
    want = needed_azimuth_bins(d, dem.grid.cell_m, part.n_az)
    assert not part.covers(want)
    for mode in ("first", "all"):
        a = caster.cast(o, d, mode=mode, coherent=True)
        assert_same(a, caster.cast(o, d, mode=mode, coherent=False))
    ix = caster.angular.get(o[0])
    assert ix is not part and ix.covers(want)
    for a in np.flatnonzero(part.slot_of_az >= 0):
        np.testing.assert_array_equal(ix.leaves(a), part.leaves(a))


def test_vertical_and_level_rays_share_an_origin():
    rng = np.random.default_rng(7)
    dem = random_dem(rng, nrows=20, ncols=20)
    x0, y0, x1, y1 = dem.grid.bounds
    c = [(x0 + x1) / 2, (y0 + y1) / 2, 30.0]
    d = np.array(
        [[0, 0, -1.0], [0, 0, 1.0], [1, 0, 0.0], [0, -1, 0.0], [1, 1, -0.2], [0, 1e-9, -1]]
    )
    o = np.tile(c, (len(d), 1))
    caster = RayCaster.from_dem(dem)
    assert_same(caster.cast(o, d, coherent=True), caster.cast(o, d, coherent=False))


# ---------------------------------------------------------------------- API and cache
def test_auto_mode_uses_indexes_only_for_long_runs():
    rng = np.random.default_rng(9)
    dem = random_dem(rng, nrows=25, ncols=25)
    caster = RayCaster.from_dem(dem)
    o, d = camera_batch(rng, dem, n_cams=1, n_az=200, n_el=101)
    assert len(o) >= MIN_COHERENT_RUN
    short = caster.cast(o[:50], d[:50])
    assert len(caster.angular) == 0
    full = caster.cast(o, d)
    assert len(caster.angular) == 1
    assert_same(full, caster.cast(o, d, coherent=False))
    np.testing.assert_array_equal(
        short.range_m, caster.cast(o[:50], d[:50], coherent=False).range_m
    )
    with pytest.raises(RaycastError):
        caster.cast(o, d, coherent="yes")


def test_cache_extends_evicts_and_reuses():
    rng = np.random.default_rng(10)
    dem = random_dem(rng, nrows=20, ncols=20)
    caster = RayCaster.from_dem(dem)
    o, d = camera_batch(rng, dem, n_cams=1)
    ix1 = caster.prepare_origin(o[0], d[: len(d) // 2])
    assert caster.prepare_origin(o[0], d[: len(d) // 2]) is ix1  # cached
    ix2 = caster.prepare_origin(o[0], d)  # more azimuths: extended, old bins kept
    assert ix2.n_slots >= ix1.n_slots
    for a in np.flatnonzero(ix1.slot_of_az >= 0):
        np.testing.assert_array_equal(ix2.leaves(a), ix1.leaves(a))
    assert ix2.covers(needed_azimuth_bins(d, dem.grid.cell_m, ix2.n_az))
    whole = caster.prepare_origin(o[0])
    assert whole.n_slots == whole.n_az and whole.nbytes > 0
    cache = AngularCache(max_origins=2)
    for z in (1.0, 2.0, 3.0):
        cache.put(full_index(dem, [0.0, 50.0, z], n_az=8))
    assert len(cache) == 2 and cache.get(np.array([0.0, 50.0, 1.0])) is None
    assert cache.get(np.array([0.0, 50.0, 3.0])) is not None
    small = AngularCache(max_bytes=1)
    small.put(full_index(dem, [0.0, 50.0, 1.0], n_az=8))
    small.put(full_index(dem, [0.0, 50.0, 2.0], n_az=8))
    assert len(small) == 1  # over budget: only the newest kept
    small.clear()
    assert len(small) == 0 and small.nbytes == 0
    with pytest.raises(RaycastError):
        caster.prepare_origin([0.0, np.nan, 1.0])
    with pytest.raises(RaycastError):
        caster.prepare_origin([0.0, 1.0, 1.0], np.zeros((3, 2)))


def test_cone_covers_the_sector():
    n_az = 64
    for first, span in ((0, 5), (60, 8), (30, 20), (10, 30), (5, 40)):
        mask = np.zeros(n_az, bool)
        mask[(first + np.arange(span)) % n_az] = True
        cone = _cone(mask)
        if span >= 30:
            assert cone[0] == 0.0  # part a turn or more: scan everything
            continue
        assert cone[0] == 1.0
        # Directions at the centre of every flagged bin lie inside the cone.
        p = (np.flatnonzero(mask) + 0.5) * 4.0 / n_az
        d0, d1 = cone[1:3], cone[3:5]
        for q in p:
            v = np.array(_dir(q))
            assert d0[0] * v[1] - d0[1] * v[0] >= 0 and v[0] * d1[1] - v[1] * d1[0] >= 0


def _dir(p):
    p %= 4.0
    return [(1 - p, p), (1 - p, 2 - p), (p - 3, 2 - p), (p - 3, p - 4)][int(p)]


# ---------------------------------------------------------------------- vectorised set-up
@pytest.mark.parametrize("where", ["inside", "west", "south-east", "below", "above"])
def test_set_up_lanes_match_the_scalar_set_up_to_the_bit(where):
    """A run's vectorised set-up (``_set_up_lanes``) gives every ray the scalar
    ``_prepare`` + ``_store_lane`` answers, bit for bit, on awkward rays: axis-aligned,
    level, vertical, tiny components, zero and finite ranges, origins off the DEM."""
    from demtrack.core.raycast._walk_kernels import BLOCK, HIT, SCRATCH_ROWS, _prepare

    rng = np.random.default_rng(11)
    dem = random_dem(rng, holes=False, nrows=17, ncols=23)
    caster = RayCaster.from_dem(dem)
    g, p = caster.grid, caster.pyramid
    x0, y0, x1, y1 = g.bounds
    mid = [(x0 + x1) / 2, (y0 + y1) / 2]
    origin = {
        "inside": [*mid, 25.0],
        "west": [x0 - 7.0, mid[1], 25.0],
        "south-east": [x1 + 3.0, y0 - 5.0, 12.0],
        "below": [*mid, -50.0],
        "above": [*mid, p.z_max + 5.0],
    }[where]
    special = np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1], [1, 1, 0]]
        + [[1e-300, 0, -1], [0, -1e-300, -1], [3, -2, -1], [-1, 1e-9, -0.3]],
        float,
    )
    d = np.vstack([special, rng.normal(size=(BLOCK - len(special), 3))])
    d[len(special) :, 2] = -np.abs(d[len(special) :, 2]) - 0.3
    max_range = np.where(np.arange(BLOCK) % 5 == 0, 0.0, np.inf)
    max_range[np.arange(BLOCK) % 5 == 1] = 9.0
    ix = caster._index_for(np.asarray(origin, float), d, 0, BLOCK)
    args = (float(g.x_min), float(g.y_max), float(g.cell_m))
    gxs = (origin[0] - args[0]) / args[2] - 0.5
    gys = (args[1] - origin[1]) / args[2] - 0.5
    below = ak._origin_below(
        caster.elevation, p.nodes, p.level_offsets, p.level_shapes, gxs, gys, origin[2]
    )
    common = (ix.d_rho, ix.n_az, ix.start.shape[1], ix.s_unit)
    R = SCRATCH_ROWS
    lane_in = np.concatenate([d.T.ravel(), max_range])
    lane_in = np.concatenate([lane_in.reshape(4, BLOCK), np.ones((4, R - BLOCK))], axis=1).ravel()
    geo = np.full(ak._GEO_FIELDS * R, np.nan)
    ent = np.full(5 * R, -7, np.int64)
    nrows, ncols = caster.elevation.shape
    ak._set_up_lanes(
        nrows, ncols, args[2], p.z_min, p.z_max, HEIGHT_MARGIN_M, gxs, gys, origin[2], below,
        *common, lane_in, geo, ent,
    )  # fmt: skip
    geo_ref, ent_ref = np.full_like(geo, np.nan), np.full_like(ent, -7)
    for j in range(BLOCK):
        prep = _prepare(
            caster.elevation, p.nodes, p.level_offsets, p.level_shapes, *args, p.z_min,
            p.z_max, HEIGHT_MARGIN_M, *origin, *d[j], max_range[j],
        )  # fmt: skip
        ak._store_lane(j, *prep, *common, geo_ref, ent_ref)
    status = ent[4 * R : 4 * R + BLOCK]
    np.testing.assert_array_equal(status, ent_ref[4 * R : 4 * R + BLOCK])
    assert where != "inside" or (status == HIT).sum() > BLOCK // 4
    for j in np.flatnonzero(status == HIT):
        lanes = j + R * np.arange(ak._GEO_FIELDS)[1:]
        np.testing.assert_array_equal(geo[lanes].view(np.int64), geo_ref[lanes].view(np.int64))
        np.testing.assert_array_equal(ent[j + R * np.arange(4)], ent_ref[j + R * np.arange(4)])
