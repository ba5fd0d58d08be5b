"""TIN gridding of sparse clouds: against scipy's Delaunay interpolator, planes, brute force."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import ConvexHull

from demtrack.core.errors import DemError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.tin import Coverage, grid_points_tin, tin_at


def plane(x, y):
    return 120.0 + 0.07 * x - 0.11 * y


def sparse(n=600, side=60.0, seed=0, z=plane):
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, side, n), rng.uniform(0, side, n)
    return np.column_stack([x, y, z(x, y)])


def test_tin_at_is_scipys_delaunay_interpolator():
    pts = sparse()
    pts[:, 2] += np.random.default_rng(1).normal(0, 0.5, len(pts))  # not a plane
    q = np.random.default_rng(2).uniform(-5, 65, (4000, 2))
    ours = tin_at(pts[:, :2], pts[:, 2], q[:, 0], q[:, 1])
    peer = LinearNDInterpolator(pts[:, :2], pts[:, 2])(q)
    assert np.array_equal(np.isnan(ours), np.isnan(peer))
    ok = np.isfinite(peer)
    assert ok.sum() > 2500 and np.max(np.abs(ours[ok] - peer[ok])) < 1e-9


@settings(max_examples=25, deadline=None)
@given(a=st.floats(-50, 50), b=st.floats(-2, 2), c=st.floats(-2, 2), seed=st.integers(0, 1000))
def test_tin_reproduces_any_plane(a, b, c, seed):
    pts = sparse(n=50, seed=seed, z=lambda x, y: a + b * x + c * y)
    q = np.random.default_rng(seed + 1).uniform(0, 60, (200, 2))
    z = tin_at(pts[:, :2], pts[:, 2], q[:, 0], q[:, 1])
    ok = np.isfinite(z)
    assert np.allclose(z[ok], a + b * q[ok, 0] + c * q[ok, 1], atol=1e-9)


def test_fit_is_exact_on_a_plane_away_from_the_hull():
    pts = sparse()
    r = grid_points_tin(pts, 1.0)
    hull = shapely.Polygon(pts[ConvexHull(pts[:, :2]).vertices, :2])
    q = np.random.default_rng(3).uniform(0, 60, (5000, 2))
    deep = shapely.contains_xy(hull.buffer(-2.0), q[:, 0], q[:, 1])
    z = r.dem.sample(q[deep, 0], q[deep, 1])
    # bilinear patches reproduce a plane, the TIN prior is the plane: the fit is exact
    assert np.max(np.abs(z - plane(q[deep, 0], q[deep, 1]))) < 1e-3  # float32 cells


def test_every_point_inside_the_hull_gets_a_value_and_holes_lie_outside():
    pts = sparse(n=300, seed=4)
    r = grid_points_tin(pts, 1.0)
    hull = shapely.Polygon(pts[ConvexHull(pts[:, :2]).vertices, :2])
    q = np.random.default_rng(5).uniform(0, 60, (20000, 2))
    inside = shapely.contains_xy(hull, q[:, 0], q[:, 1])
    assert np.isfinite(r.dem.sample(q[inside, 0], q[inside, 1])).all()
    # brute force: a hole's centre is more than one cell (Chebyshev) from the hull
    g = r.dem.grid
    ex, ny = g.centres()
    hx, hy = ex[r.dem.nodata], ny[r.dem.nodata]
    box = shapely.box(hx - g.cell_m, hy - g.cell_m, hx + g.cell_m, hy + g.cell_m)
    assert not shapely.intersects(box, hull).any()
    # and every cell within one cell of the hull has a value
    vx, vy = ex[~r.dem.nodata], ny[~r.dem.nodata]
    assert shapely.intersects(shapely.box(vx - 1, vy - 1, vx + 1, vy + 1), hull).all()


def test_coverage_counts_and_per_cell_statistics_are_kept():
    rng = np.random.default_rng(6)
    pts = sparse(n=400, seed=6)
    pts[:, 2] += rng.normal(0, 0.05, len(pts))
    r = grid_points_tin(pts, 1.0)
    dem = r.dem
    cov = r.coverage
    assert cov == Coverage.of(dem)
    assert cov.with_points + cov.interpolated + cov.holes == cov.cells == dem.elevation.size
    # the paper's statistics, brute force: count and population variance per cell
    rows, cols = dem.grid.cell_of(pts[:, 0], pts[:, 1])
    for r_, c_ in list(zip(rows, cols, strict=True))[:60]:
        z = pts[(rows == r_) & (cols == c_), 2]
        assert dem.count[r_, c_] == len(z)
        assert dem.variance[r_, c_] == pytest.approx(np.var(z), abs=1e-4)
    assert cov.with_points == len(set(zip(rows, cols, strict=True)))
    assert (dem.filled == ((dem.count == 0) & ~dem.nodata)).all()
    assert np.isfinite(dem.variance[dem.filled]).all()


def test_surface_model_keeps_the_highest_return_per_cell():
    pts = sparse(n=800, seed=7)
    pts[::3, 2] += 5.0  # canopy returns above the ground ones
    r = grid_points_tin(pts, 2.0, statistic="max", method="sample")
    rows, cols = r.dem.grid.cell_of(pts[:, 0], pts[:, 1])
    top = {}
    for r_, c_, z in zip(rows, cols, pts[:, 2], strict=True):
        top[(r_, c_)] = max(top.get((r_, c_), -np.inf), z)
    got = np.array([r.dem.elevation[k] for k in top])
    assert np.allclose(got, list(top.values()), atol=1e-4)


def test_tin_grid_beats_the_per_cell_mean_on_sparse_points():
    # 0.4 points per m^2 on rolling terrain: the mean leaves most cells holes.
    def hills(x, y):
        return 100 + 3 * np.sin(x / 9.0) * np.cos(y / 13.0)

    pts = sparse(n=1440, seed=8, z=hills)
    r = grid_points_tin(pts, 1.0)
    mean = Dem.from_points(pts, 1.0, bounds=r.dem.grid.bounds)
    assert mean.nodata.mean() > 0.6 and r.coverage.holes / r.coverage.cells < 0.15


def test_too_few_or_collinear_points_are_refused():
    with pytest.raises(DemError, match="at least 3"):
        grid_points_tin(np.zeros((2, 3)), 1.0)
    line = np.column_stack([np.arange(10.0), np.arange(10.0), np.zeros(10)])
    with pytest.raises(DemError, match="collinear"):
        grid_points_tin(line, 1.0)
    with pytest.raises(DemError, match="statistic"):
        grid_points_tin(sparse(), 1.0, statistic="median")  # type: ignore[arg-type]
