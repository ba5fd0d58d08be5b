"""The polyline projection kernel against shapely (GEOS) and its numpy twin: the same bits.

The convoy test used ``shapely.distance(points, line)`` and
``shapely.line_locate_point(line, points)``; the kernel must answer both exactly as GEOS
does, ties included (GEOS locates a point on the first of equally near segments).
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.activity._polyline_kernels import project_points_kernel, project_points_reference


def _kernel(line_xy: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dist, along = np.empty(len(xy)), np.empty(len(xy))
    project_points_kernel(
        np.ascontiguousarray(line_xy[:, 0]),
        np.ascontiguousarray(line_xy[:, 1]),
        np.ascontiguousarray(xy[:, 0]),
        np.ascontiguousarray(xy[:, 1]),
        dist,
        along,
    )
    return dist, along


def _geos(line_xy: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    line = shapely.LineString(line_xy)
    pts = shapely.points(xy[:, 0], xy[:, 1])
    return shapely.distance(pts, line), shapely.line_locate_point(line, pts)


def _same_bits(got: tuple[np.ndarray, ...], want: tuple[np.ndarray, ...]) -> None:
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g.view(np.int64), w.view(np.int64))


def _line(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "scattered":
        return rng.normal(0, 100, (n, 2)) + 1000.0
    if kind == "walk":  # a track-like path far from the origin
        return np.cumsum(rng.normal(0, 3, (n, 2)), axis=0) + rng.normal(0, 500, 2)
    if kind == "grid":  # integer vertices: repeats, collinear overlaps, many ties
        return rng.integers(0, 6, (n, 2)).astype(float)
    if kind == "repeats":  # zero-length segments
        path = np.cumsum(rng.normal(0, 2, (n, 2)), axis=0)
        return np.repeat(path, rng.integers(1, 4, n), axis=0)
    if kind == "back-and-forth":  # the path runs over itself
        return np.column_stack([np.cumsum(rng.choice([-1.0, 1.0, 0.5], n)), np.zeros(n)])
    angle = np.linspace(0, 2 * np.pi, n)  # a closed loop
    return np.column_stack([10 * np.cos(angle), 10 * np.sin(angle)]) + 300.0


@pytest.mark.parametrize("kind", ["scattered", "walk", "grid", "repeats", "back-and-forth", "loop"])
@pytest.mark.parametrize("seed", range(4))
def test_kernel_gives_geos_bits(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    line_xy = _line(kind, int(rng.integers(2, 50)), rng)
    lo, hi = line_xy.min(axis=0) - 5, line_xy.max(axis=0) + 5
    xy = np.vstack(
        [
            rng.uniform(lo, hi, (300, 2)),
            line_xy,  # on the vertices
            (line_xy[:-1] + line_xy[1:]) / 2,  # on the segments
            line_xy + rng.normal(0, 1e-9, line_xy.shape),
            rng.integers(-1, 7, (100, 2)) / 2.0,  # half-integers: equidistant ties
        ]
    )
    want = _geos(line_xy, xy)
    _same_bits(_kernel(line_xy, xy), want)
    _same_bits(project_points_reference(line_xy, xy), want)


@settings(max_examples=80, deadline=None)
@given(
    line=st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), min_size=2, max_size=8).map(
        lambda v: np.array(v, float)
    ),
    pts=st.lists(st.tuples(st.integers(-8, 8), st.integers(-8, 8)), min_size=1, max_size=20).map(
        lambda v: np.array(v, float) / 2
    ),
)
def test_kernel_ties_and_degenerate_lines(line: np.ndarray, pts: np.ndarray) -> None:
    """Small integer lines (one repeated point included: a stopped leader) and
    half-integer points."""
    want = _geos(line, pts)
    _same_bits(_kernel(line, pts), want)
    _same_bits(project_points_reference(line, pts), want)


def test_kernel_no_points() -> None:
    dist, along = _kernel(np.array([[0.0, 0.0], [1.0, 1.0]]), np.zeros((0, 2)))
    assert dist.shape == along.shape == (0,)
