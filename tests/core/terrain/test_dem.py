from __future__ import annotations

import numpy as np
import pytest
import rasterio
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import DemError, DemtrackError, InputFileError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec


def _reference_stats(xyz, grid):
    """Per-cell mean / variance / count with a plain Python dictionary."""
    cells: dict[tuple[int, int], list[float]] = {}
    for x, y, z in xyz:
        c = int(np.floor((x - grid.x_min) / grid.cell_m))
        r = int(np.floor((grid.y_max - y) / grid.cell_m))
        if 0 <= r < grid.nrows and 0 <= c < grid.ncols:
            cells.setdefault((r, c), []).append(z)
    mean = np.full(grid.shape, np.nan)
    var = np.full(grid.shape, np.nan)
    cnt = np.zeros(grid.shape, int)
    for (r, c), zs in cells.items():
        mean[r, c] = np.mean(zs)
        var[r, c] = np.var(zs)
        cnt[r, c] = len(zs)
    return mean, var, cnt


def test_from_points_matches_reference_statistics():
    rng = np.random.default_rng(0)
    xyz = np.column_stack(
        [rng.uniform(3, 13, 4000), rng.uniform(-7, 2, 4000), rng.normal(300, 2, 4000)]
    )
    dem = Dem.from_points(xyz, cell_size=0.5)
    assert dem.grid.x_min == 3.0 and dem.grid.y_min == -7.0
    mean, var, cnt = _reference_stats(xyz, dem.grid)
    np.testing.assert_array_equal(dem.count, cnt)
    np.testing.assert_allclose(dem.elevation, mean, rtol=0, atol=1e-4, equal_nan=True)
    np.testing.assert_allclose(dem.variance, var, rtol=1e-4, atol=1e-4, equal_nan=True)
    assert dem.count.sum() == len(xyz)


def test_from_points_with_bounds_drops_outside_points_and_keeps_edges():
    # Cells are half-open: [x_min, x_max) x (y_min, y_max]; a point on the south edge is out.
    xyz = np.array(
        [[0.0, 0.2, 1.0], [0.99, 0.99, 3.0], [1.0, 0.5, 7.0], [-0.1, 0.5, 9.0], [0.5, 0.0, 11.0]]
    )
    dem = Dem.from_points(xyz, cell_size=1.0, bounds=(0, 0, 2, 1))
    assert dem.grid.shape == (1, 2)
    assert dem.elevation[0, 0] == pytest.approx(2.0)
    assert dem.variance[0, 0] == pytest.approx(1.0)
    assert dem.elevation[0, 1] == pytest.approx(7.0)  # x = 1.0 falls east of the edge
    assert dem.count.sum() == 3


def test_from_points_variance_is_accurate_for_large_offsets():
    # A naive E[z^2] - E[z]^2 loses all precision here; two passes must not.
    z = 1.0e5 + np.array([0.0, 0.01, 0.02, 0.03])
    xyz = np.column_stack([np.full(4, 0.1), np.full(4, 0.1), z])
    dem = Dem.from_points(xyz, cell_size=0.5)
    assert dem.variance[0, 0] == pytest.approx(np.var(z - 1e5), rel=1e-3)


def test_from_points_rejects_bad_shapes():
    with pytest.raises(DemError, match="shape"):
        Dem.from_points(np.zeros((5, 2)))
    with pytest.raises(DemError, match="no finite points"):
        Dem.from_points(np.full((3, 3), np.nan))


def _plane_dem(a=0.3, b=-0.2, c=100.0, shape=(12, 15), cell=0.5):
    grid = GridSpec(10.0, 50.0, cell, *shape)
    x, y = grid.centres()
    return Dem(grid, (a * x + b * y + c).astype(np.float32)), (a, b, c)


def test_sample_is_exact_on_a_plane_and_nan_outside_centre_hull():
    dem, (a, b, c) = _plane_dem()
    rng = np.random.default_rng(1)
    xmin, ymin, xmax, ymax = dem.grid.centre_bounds
    x = rng.uniform(xmin, xmax, 500)
    y = rng.uniform(ymin, ymax, 500)
    np.testing.assert_allclose(dem.sample(x, y), a * x + b * y + c, atol=2e-5)
    assert np.isnan(dem.sample(np.array([xmin - 1e-6]), np.array([ymin + 1]))).all()
    assert np.isfinite(dem.sample(np.array([xmax]), np.array([ymax]))).all()


@settings(max_examples=50, deadline=None)
@given(st.floats(0, 1), st.floats(0, 1))
def test_sample_reproduces_cell_centre_values_and_bilinear_midpoints(s, t):
    rng = np.random.default_rng(2)
    grid = GridSpec(0.0, 2.0, 1.0, 2, 2)
    z = rng.normal(size=(2, 2)).astype(np.float32)
    dem = Dem(grid, z)
    x, y = grid.from_grid(np.array([s]), np.array([t]))
    expected = (
        z[0, 0] * (1 - s) * (1 - t)
        + z[0, 1] * s * (1 - t)
        + z[1, 0] * (1 - s) * t
        + z[1, 1] * s * t
    )
    assert dem.sample(x, y)[0] == pytest.approx(expected, abs=1e-6)


def test_sample_is_nan_next_to_a_hole():
    dem, _ = _plane_dem()
    elev = np.array(dem.elevation)
    elev[5, 5] = np.nan
    holey = Dem(dem.grid, elev)
    x, y = dem.grid.from_grid(np.array([4.5, 5.5, 7.5]), np.array([4.5, 5.5, 7.5]))
    s = holey.sample(x, y)
    assert np.isnan(s[0]) and np.isnan(s[1]) and np.isfinite(s[2])
    assert np.isnan(holey.variance[5, 5])


def test_fill_holes_interpolates_a_coarse_plane_exactly():
    fine, (a, b, c) = _plane_dem(shape=(40, 40), cell=0.5)
    elev = np.array(fine.elevation)
    elev[10:20, 5:30] = np.nan
    holey = Dem(fine.grid, elev, count=np.where(np.isnan(elev), 0, 1))
    cgrid = GridSpec(-20.0, 80.0, 30.0, 3, 3)  # 30 m cells covering the fine grid
    cx, cy = cgrid.centres()
    coarse = Dem(cgrid, (a * cx + b * cy + c).astype(np.float32))
    filled = holey.fill_holes(coarse, coarse_sigma_m=2.0)
    np.testing.assert_allclose(filled.elevation, fine.elevation, atol=1e-4)
    assert filled.filled.sum() == 10 * 25
    assert filled.variance[15, 15] == pytest.approx(4.0)
    assert filled.coverage == pytest.approx(1 - 250 / 1600)


def test_geotiff_round_trip_keeps_all_bands_and_georeferencing(tmp_path):
    rng = np.random.default_rng(3)
    xyz = np.column_stack(
        [rng.uniform(0, 20, 3000), rng.uniform(0, 10, 3000), rng.normal(5, 1, 3000)]
    )
    dem = Dem.from_points(xyz, 0.5)
    cgrid = GridSpec(-30.0, 40.0, 30.0, 3, 3)
    coarse = Dem(cgrid, np.full((3, 3), 5.0, np.float32))
    dem = dem.fill_holes(coarse)
    path = tmp_path / "dem.tif"
    dem.write(path)
    with rasterio.open(path) as src:
        assert src.count == 3
        assert src.transform == dem.grid.transform
        assert src.descriptions[0] == "elevation_m"
    back = Dem.read(path)
    assert back.grid == dem.grid
    np.testing.assert_array_equal(back.elevation, dem.elevation)
    np.testing.assert_array_equal(back.variance, dem.variance)
    np.testing.assert_array_equal(back.count, dem.count)
    np.testing.assert_array_equal(back.filled, dem.filled)
    assert back.vertical_datum == dem.vertical_datum


def test_read_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(InputFileError, match="cannot read DEM"):
        Dem.read(tmp_path / "nope.tif")


def test_constructor_validates_shapes():
    grid = GridSpec(0.0, 1.0, 0.5, 2, 2)
    with pytest.raises(DemError, match="shape"):
        Dem(grid, np.zeros((3, 2)))
    with pytest.raises(DemtrackError):
        Dem(grid, np.zeros((2, 2)), variance=np.zeros((1, 1)))
    with pytest.raises(ValueError, match="positive"):
        GridSpec(0.0, 1.0, 0.0, 2, 2)


def test_ray_caster_is_built_once_and_not_carried_into_a_changed_dem():
    grid = GridSpec(0.0, 4.0, 1.0, 4, 4)
    elev = np.zeros((4, 4), np.float32)
    elev[1, 1] = np.nan
    dem = Dem(grid, elev)
    caster = dem.ray_caster()
    assert dem.ray_caster() is caster
    filled = dem.fill_holes(Dem(grid, np.ones((4, 4), np.float32)))
    assert filled.ray_caster() is not caster
    assert filled.ray_caster().elevation[1, 1] == 1.0
