"""Where a ray passes over a DEM hole: analytic cases on a flat DEM with a known hole."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.geolocation.hole_crossing import first_hole_crossing
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec


def flat_with_hole(rows=slice(8, 12), cols=slice(30, 34)):
    grid = GridSpec(0.0, 40.0, 1.0, 40, 60)  # E 0..60, N 0..40, centres at .5
    z = np.zeros(grid.shape, np.float32)
    z[rows, cols] = np.nan
    return Dem(grid, z)


def test_the_first_hole_cell_and_the_distance_along_the_ray():
    dem = flat_with_hole()
    # due east along row 10 (N = 40 - 10.5 = 29.5), from E 2.5, level, 1 m below the top
    o = np.array([2.5, 29.5, -1.0])  # below the terrain top (0): a crossing could be missed
    hole = first_hole_crossing(dem, o, np.array([1.0, 0.0, 0.0]))
    assert hole is not None
    # the hole's first column is 30 (centre E 30.5); the surface is undefined from the
    # centre of column 29 on (E 29.5): the patch there has a NaN corner
    assert hole.e_m == 30.5 and hole.n_m == 29.5
    assert 29.5 - 2.5 - 0.25 < hole.range_m <= 29.5 - 2.5 + 0.25  # walked in quarter cells
    assert "E 30.5 N 29.5 m" in hole.describe()


def test_slanted_ray_range_is_along_the_ray_not_horizontal():
    dem = flat_with_hole()
    d = np.array([3.0, 0.0, 4.0])  # 5 m along the ray per 3 m east, rising from below
    hole = first_hole_crossing(dem, np.array([2.5, 29.5, -40.0]), d)
    assert hole is not None
    assert hole.range_m == pytest.approx((29.5 - 2.5) * 5.0 / 3.0, abs=0.25 * 5.0 / 3.0)


def test_no_hole_under_the_ray_or_ray_above_the_terrain():
    dem = flat_with_hole()
    # along row 30: the hole is in rows 8..11
    assert first_hole_crossing(dem, np.array([2.5, 9.5, -1.0]), np.array([1.0, 0, 0])) is None
    # over the hole but 1 m above the highest terrain: no crossing can be missed
    assert first_hole_crossing(dem, np.array([2.5, 29.5, 1.0]), np.array([1.0, 0, 0])) is None
    # stopped before it
    assert (
        first_hole_crossing(dem, np.array([2.5, 29.5, -1.0]), np.array([1.0, 0, 0]), 20.0) is None
    )
    full = Dem(dem.grid, np.zeros(dem.grid.shape, np.float32))
    assert first_hole_crossing(full, np.array([2.5, 29.5, -1.0]), np.array([1.0, 0, 0])) is None
