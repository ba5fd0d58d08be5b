"""Large incoherent batches are cast in a sorted order; the answers are those of ray order."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from raycast_checks import assert_identical_hits

from demtrack.core.raycast import _ray_kernels as kernels
from demtrack.core.raycast import cast as raycast
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.terrain.grid import GridSpec


@dataclass(frozen=True)
class FakeDem:
    grid: GridSpec
    elevation: np.ndarray


def hilly_dem(rng, nrows=150, ncols=170, cell=0.5) -> FakeDem:
    yy, xx = np.mgrid[0:nrows, 0:ncols]
    elev = 5.0 * np.sin(xx / 13.0) * np.cos(yy / 9.0) + rng.normal(0.0, 0.3, (nrows, ncols))
    elev = elev.astype(np.float32)
    elev[rng.random((nrows, ncols)) < 0.01] = np.nan
    return FakeDem(GridSpec(-20.0, 60.0, cell, nrows, ncols), elev)


def random_rays(rng, dem: FakeDem, n: int):
    x0, y0, x1, y1 = dem.grid.bounds
    o = np.column_stack(
        [rng.uniform(x0 - 5, x1 + 5, n), rng.uniform(y0 - 5, y1 + 5, n), rng.uniform(-3.0, 30.0, n)]
    )
    d = rng.normal(size=(n, 3))
    d[:, 2] = -np.abs(d[:, 2]) * rng.uniform(0.05, 1.0, n)
    d[::97, :2] = 0.0  # vertical rays too
    return o, d


def test_ray_order_kernel_sorts_and_copies():
    rng = np.random.default_rng(0)
    dem = hilly_dem(rng, nrows=300, ncols=400)
    o, d = random_rays(rng, dem, 5000)
    mr = rng.uniform(0.0, 100.0, len(o))
    g = dem.grid
    copies = (np.empty_like(o), np.empty_like(d), np.empty_like(mr))
    order = kernels.ray_order_kernel(
        o, d, mr, float(g.x_min), float(g.y_max), float(g.cell_m), *g.shape, 1, *copies
    )
    np.testing.assert_array_equal(np.sort(order), np.arange(len(o)))
    # Each thread sorts its share of the rays into its own slots: the same order.
    for threads in (2, 3):
        geo = (float(g.x_min), float(g.y_max), float(g.cell_m), *g.shape, threads)
        other = kernels.ray_order_kernel(o, d, mr, *geo, *(np.empty_like(a) for a in copies))
        np.testing.assert_array_equal(other, order)
    np.testing.assert_array_equal(copies[0], o[order])
    np.testing.assert_array_equal(copies[1], d[order])
    np.testing.assert_array_equal(copies[2], mr[order])
    # Grouped: the origin tiles (clipped to the grid) never decrease along the order.
    sh = kernels.ORDER_TILE_SHIFT
    gx = np.clip((o[order, 0] - g.x_min) / g.cell_m, 0, g.ncols - 1).astype(int) >> sh
    gy = np.clip((g.y_max - o[order, 1]) / g.cell_m, 0, g.nrows - 1).astype(int) >> sh
    tile = gy * (((g.ncols - 1) >> sh) + 1) + gx
    assert np.all(np.diff(tile) >= 0)


@pytest.mark.parametrize("mode", ["first", "all"])
def test_sorted_cast_is_bit_identical_to_ray_order(monkeypatch, mode):
    rng = np.random.default_rng(1)
    dem = hilly_dem(rng)
    o, d = random_rays(rng, dem, 6000)
    mr = np.where(rng.random(len(o)) < 0.3, rng.uniform(0.0, 50.0, len(o)), np.inf)
    caster = RayCaster.from_dem(dem)
    monkeypatch.setattr(raycast, "MIN_ORDERED_RAYS", 10**12)
    plain = caster.cast(o, d, mr, mode=mode, max_hits=5)
    monkeypatch.setattr(raycast, "MIN_ORDERED_RAYS", 1)
    sorted_ = caster.cast(o, d, mr, mode=mode, max_hits=5)
    assert np.count_nonzero(plain.status == raycast.HIT) > 1000
    if mode == "all":
        assert plain.truncated.any() and (plain.counts > 1).sum() > 100
    assert_identical_hits(plain, sorted_)
    # The light kernels (one thread, ray order) agree bit for bit as well.
    with raycast.light_kernels():
        light = caster.cast(o, d, mr, mode=mode, max_hits=5)
    assert_identical_hits(light, sorted_)
