"""The light casting kernels give the fast kernels' answers bit for bit; the switch."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from raycast_checks import assert_identical_hits

from demtrack.core.raycast import cast as raycast
from demtrack.core.raycast.cast import RayCaster, cast_rays
from demtrack.core.raycast.light import light_kernels, light_kernels_on, use_light_kernels
from demtrack.core.raycast.reference import cast_rays_reference
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.warm import warm_raycast as warm_up


@dataclass(frozen=True)
class FakeDem:
    grid: GridSpec
    elevation: np.ndarray


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


def assert_same(a, b, tol=1e-6):
    """Same statuses and hit counts, ranges and points within ``tol`` (m)."""
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_allclose(a.range_m, b.range_m, rtol=0, atol=tol)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=tol)
    np.testing.assert_array_equal(a.truncated, b.truncated)
    np.testing.assert_array_equal(a.crossed_nodata, b.crossed_nodata)


@pytest.fixture(autouse=True)
def _fast_after_each_test():
    yield
    use_light_kernels(False)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("mode", ["first", "all"])
def test_light_kernels_match_the_fast_ones_bit_for_bit(seed, mode):
    rng = np.random.default_rng(seed)
    dem = random_dem(rng)
    o, d = random_rays(rng, dem, 3000)
    rng_m = np.where(rng.random(len(o)) < 0.2, rng.uniform(0, 40, len(o)), np.inf)
    fast = cast_rays(dem, o, d, rng_m, mode=mode, max_hits=5)
    with light_kernels():
        light = cast_rays(dem, o, d, rng_m, mode=mode, max_hits=5)
    assert_identical_hits(light, fast)
    # And the numpy twin agrees (the usual tolerance of the ray-caster tests).
    with light_kernels():
        some = cast_rays(dem, o[:300], d[:300], rng_m[:300], mode=mode, max_hits=5)
    assert_same(
        some, cast_rays_reference(dem, o[:300], d[:300], rng_m[:300], mode=mode, max_hits=5)
    )


def test_light_refill_of_rays_with_many_crossings():
    zig = np.tile(np.array([0.0, 10.0], np.float32), 20)
    dem = make_dem(np.vstack([zig, zig, zig]))
    o = np.array([[0.5, 1.5, 5.0], [0.5, 1.4, 5.0]])
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.01, 0.0]])
    with light_kernels():
        light = cast_rays(dem, o, d)
        cut = cast_rays(dem, o, d, max_hits=3)
    assert light.counts[0] == 20  # more than the first pass keeps: re-walked
    assert_identical_hits(light, cast_rays(dem, o, d))
    assert_identical_hits(cut, cast_rays(dem, o, d, max_hits=3))
    assert_same(light, cast_rays_reference(dem, o, d))


def test_light_casts_build_no_angular_index_unless_asked():
    rng = np.random.default_rng(3)
    dem = random_dem(rng, holes=False, nrows=40, ncols=40)
    n = raycast.MIN_COHERENT_RUN + 10
    o = np.tile([[0.0, 50.0, 60.0]], (n, 1))  # one origin: a coherent run
    d = np.column_stack([rng.normal(size=n), rng.normal(size=n), -rng.uniform(0.3, 1.0, n)])
    caster = RayCaster.from_dem(dem)
    with light_kernels():
        light = caster.cast(o, d, mode="first")
    assert len(caster.angular) == 0
    fast = caster.cast(o, d, mode="first")
    assert len(caster.angular) == 1  # the fast path indexes the run
    assert_same(light, fast, tol=1e-9)


def test_the_switch_restores_and_warm_up_turns_it_off():
    assert not light_kernels_on()
    with light_kernels():
        assert light_kernels_on()
        with light_kernels():
            pass
        assert light_kernels_on()
    assert not light_kernels_on()
    use_light_kernels(True)
    assert light_kernels_on()
    warm_up(angular=False)
    assert not light_kernels_on()
