"""The fast viewshed: sweep kernel against its numpy twin, and against exact sight lines."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.bench.synthetic_terrain import synthetic_dem
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CameraError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.visibility._viewshed_kernels import sweep_margin_kernel
from demtrack.core.visibility.reference import sweep_margin_reference
from demtrack.core.visibility.viewshed import PanTiltLimits, viewshed

INTR = Intrinsics(100.0, 100.0, 99.5, 74.5, 200, 150)
ALL_ROUND = PanTiltLimits(tilt_min_deg=-90.0, tilt_max_deg=90.0)


def bumpy(seed: int, n: int = 60, cell: float = 1.0, holes: bool = False) -> Dem:
    """Rough random terrain: smooth hills, blocks and spikes."""
    rng = np.random.default_rng(seed)
    grid = GridSpec(0.0, n * cell, cell, n, n)
    x, y = np.meshgrid(np.arange(n), np.arange(n))
    z = 3.0 * np.sin(x / rng.uniform(4, 9)) * np.cos(y / rng.uniform(4, 9))
    for _ in range(6):
        r, c = rng.integers(0, n - 6, 2)
        z[r : r + rng.integers(1, 6), c : c + rng.integers(1, 6)] += rng.uniform(2, 8)
    z += (rng.random((n, n)) < 0.02) * rng.uniform(0, 6, (n, n))
    if holes:
        z[rng.integers(0, n), rng.integers(0, n - 3) :][:3] = np.nan
    return Dem(grid, z.astype(np.float32))


def camera_at(dem: Dem, e: float, n: float, above_m: float) -> Camera:
    z = float(dem.sample(np.array([e]), np.array([n]))[0]) + above_m
    return Camera.from_azimuth_tilt_roll(INTR, [e, n, z], 0.0, 0.0, 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_sweep_kernel_matches_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    dem = bumpy(seed, n=int(rng.integers(12, 40)), holes=seed == 3)
    nrows, ncols = dem.grid.shape
    ogx, ogy = rng.uniform(0, ncols - 1), rng.uniform(0, nrows - 1)
    if seed == 0:
        ogx, ogy = 0.0, float(nrows - 1)  # a corner: one quadrant has everything
    z_obs = float(np.nanmax(dem.elevation)) * rng.uniform(0.3, 1.2) + 2.0
    curv = 0.0 if seed % 2 else 6.8e-8
    got = np.empty(dem.grid.shape, np.float32)
    got_slack = np.empty(dem.grid.shape, np.float32)
    sweep_margin_kernel(dem.elevation, ogx, ogy, z_obs, 1.0, 1.5, curv, got, got_slack)
    want, want_slack = sweep_margin_reference(dem.elevation, ogx, ogy, z_obs, 1.0, 1.5, curv)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    ok = ~np.isnan(want)
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(got_slack[ok], want_slack[ok], rtol=1e-5, atol=1e-3)
    assert want_slack[ok].max() > 0.1  # the interpolation does leave doubt somewhere
    if seed == 3:
        assert np.isnan(want).sum() > 1  # holes leave cells undecided (re-checked exactly)


@pytest.mark.parametrize(
    ("seed", "above_m", "target_m"), [(0, 2.0, 0.0), (1, 5.0, 1.7), (2, 15.0, 1.0), (3, 3.0, 0.5)]
)
def test_sweep_agrees_with_exact_on_random_terrain(seed, above_m, target_m):
    dem = bumpy(seed, n=90, holes=seed == 3)
    rng = np.random.default_rng(seed)
    e, n = rng.uniform(5, 85, 2)
    cam = camera_at(dem, e, n, above_m)
    kw = {"mode": "reachable", "target_height_m": target_m, "max_range_m": 200.0}
    fast = viewshed(dem, cam, method="sweep", limits=ALL_ROUND, **kw)
    exact = viewshed(dem, cam, method="exact", limits=ALL_ROUND, **kw)
    assert 0.05 < exact.mean() < 0.95  # a real mix of seen and hidden
    assert np.mean(fast == exact) >= 0.999


def test_sweep_agrees_with_exact_on_the_benchmark_terrain():
    syn = synthetic_dem(300, seed=4)
    dem = Dem(syn.grid, syn.elevation)
    for k, (fx, fy) in enumerate([(0.37, 0.41), (0.8, 0.15), (0.05, 0.95)]):
        g = dem.grid
        cam = camera_at(dem, g.x_min + fx * g.ncols * g.cell_m, g.y_max - fy * g.nrows * g.cell_m,
                        10.0 + 5 * k)  # fmt: skip
        kw = {"mode": "reachable", "target_height_m": 1.7, "max_range_m": 400.0}
        fast = viewshed(dem, cam, limits=ALL_ROUND, **kw)
        exact = viewshed(dem, cam, method="exact", limits=ALL_ROUND, **kw)
        assert np.mean(fast == exact) >= 0.999


def test_wall_shadow_is_exact_down_to_the_shadow_line():
    grid = GridSpec(-40.0, 40.0, 1.0, 80, 80)
    x, y = grid.centres()
    z = np.zeros(grid.shape, np.float32)
    wall_h, z_obs, th = 6.0, 10.0, 0.5
    z[(x > 9) & (x < 12) & (np.abs(y) < 20)] = wall_h  # centres 9.5 .. 11.5: flat top
    dem = Dem(grid, z)
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, z_obs], 90.0, -20.0, 0.0)
    # The binding edge is the wall top's far side x = 11.5: the sight line to a target at
    # x_t crosses it at height z_obs + (th - z_obs) * 11.5 / x_t.
    behind = (x > 12.5) & (np.abs(y * 11.5 / np.maximum(x, 1e-9)) < 18.0)
    clear_h = z_obs + (th - z_obs) * 11.5 / np.maximum(x, 1e-9)
    analytic = clear_h > wall_h
    x_shadow = 11.5 * (z_obs - th) / (z_obs - wall_h)
    sure = behind & (np.abs(x - x_shadow) > 0.05)
    for method in ("sweep", "exact"):
        seen = viewshed(dem, cam, mode="reachable", target_height_m=th, max_range_m=100.0,
                        method=method)  # fmt: skip
        np.testing.assert_array_equal(seen[sure], analytic[sure])
    assert analytic[sure].sum() > 50 and (~analytic[sure]).sum() > 300


def test_fov_mode_and_observer_off_the_dem_agree_with_exact():
    dem = bumpy(5, n=60)
    cam = Camera.from_azimuth_tilt_roll(INTR, [30.0, 5.0, 12.0], 10.0, -15.0, 0.0)
    fast = viewshed(dem, cam, mode="fov", target_height_m=1.0)
    exact = viewshed(dem, cam, mode="fov", target_height_m=1.0, method="exact")
    assert fast.sum() > 100 and np.mean(fast == exact) >= 0.999
    outside = Camera.from_azimuth_tilt_roll(INTR, [-20.0, 30.0, 12.0], 90.0, -10.0, 0.0)
    kw = {"mode": "reachable", "target_height_m": 1.0}
    np.testing.assert_array_equal(
        viewshed(dem, outside, **kw), viewshed(dem, outside, method="exact", **kw)
    )


def test_progress_is_reported_up_to_one():
    dem = bumpy(6, n=50)
    cam = camera_at(dem, 25.0, 25.0, 4.0)
    for method in ("sweep", "exact"):
        seen: list[float] = []
        viewshed(dem, cam, mode="reachable", method=method, progress=seen.append)
        assert seen[-1] == 1.0 and len(seen) >= 2
        assert all(b >= a for a, b in zip(seen, seen[1:], strict=False))


def test_unknown_method_is_rejected():
    dem = bumpy(7, n=20)
    with pytest.raises(CameraError, match="unknown viewshed method 'fast'"):
        viewshed(dem, camera_at(dem, 10.0, 10.0, 3.0), method="fast")
