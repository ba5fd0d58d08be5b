"""Resampling methods and the largest rectangle inside a footprint: analytic and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from affine import Affine

from demtrack.core.errors import DemError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.terrain.crs_import import resample_at_centres, warp_to_local
from demtrack.core.terrain.dem_import import largest_data_rectangle
from demtrack.core.terrain.grid import GridSpec

T = Affine(2.0, 0.0, 1000.0, 0.0, -2.0, 2000.0)  # 2 m pixels


def centres(nr, nc):
    cols, rows = np.meshgrid(np.arange(nc) + 0.5, np.arange(nr) + 0.5)
    return T @ (cols, rows)


def quadratic(x, y):
    return 0.002 * (x - 1040) ** 2 - 0.003 * (x - 1040) * (y - 1960) + 0.5 * y


def test_cubic_passes_through_centres_and_is_exact_on_quadratics():
    x, y = centres(40, 40)
    v = quadratic(x, y)
    assert np.allclose(resample_at_centres(v, T, x, y, "cubic"), v, atol=1e-9)
    rng = np.random.default_rng(0)
    qx, qy = rng.uniform(1006, 1074, 2000), rng.uniform(1926, 1994, 2000)  # 2 px inside
    got = resample_at_centres(v, T, qx, qy, "cubic")
    assert np.max(np.abs(got - quadratic(qx, qy))) < 1e-9
    # bilinear is not exact on the curvature: the cubic's advantage is real
    lin = resample_at_centres(v, T, qx, qy, "bilinear")
    assert np.max(np.abs(lin - quadratic(qx, qy))) > 1e-3


def test_nearest_is_the_cell_containing_the_point():
    v = np.arange(12.0).reshape(3, 4)
    # pixel corners: col 0 spans x 1000..1002, row 0 spans y 2000..1998
    qx, qy = np.array([1000.1, 1007.9, 1003.0]), np.array([1999.9, 1994.1, 1997.0])
    got = resample_at_centres(v, T, qx, qy, "nearest")
    assert got.tolist() == [0.0, 11.0, 5.0]
    off = resample_at_centres(
        v, T, np.array([999.9, 1008.1]), np.array([1999.0, 1999.0]), "nearest"
    )
    out = off
    assert np.isnan(out).all()


def test_a_nan_in_the_support_poisons_the_sample():
    x, y = centres(10, 10)
    v = quadratic(x, y)
    v[5, 5] = np.nan
    near = resample_at_centres(v, T, np.array([1009.0]), np.array([1991.0]), "cubic")
    assert np.isnan(near).all()  # 4 x 4 support reaches the NaN
    far = resample_at_centres(v, T, np.array([1003.0]), np.array([1997.0]), "cubic")
    assert np.isfinite(far).all()
    with pytest.raises(DemError, match="resampling"):
        resample_at_centres(v, T, x, y, "lanczos")


def test_average_of_a_plane_over_a_cell_is_its_centre_value():
    frame = LocalFrame(40.3573, -79.6208, 300.0)
    src = np.fromfunction(lambda r, c: 300.0 + 0.2 * c - 0.1 * r, (200, 200))
    from pyproj import Transformer

    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(
        -79.6208, 40.3573
    )
    t = Affine(1.0, 0.0, x - 100.0, 0.0, -1.0, y + 100.0)
    grid = GridSpec(-40.0, 40.0, 8.0, 10, 10)
    bil = warp_to_local(src, t, "EPSG:32617", frame, grid)
    avg = warp_to_local(src, t, "EPSG:32617", frame, grid, resampling="average")
    assert np.isfinite(avg).all()
    assert np.max(np.abs(avg - bil)) < 2e-3  # a plane's mean over a cell is its centre


def brute_rectangle_area(mask):
    best = 0
    nr, nc = mask.shape
    for r0 in range(nr):
        for r1 in range(r0 + 1, nr + 1):
            cols = mask[r0:r1].all(axis=0)
            run = 0
            for ok in cols:
                run = run + 1 if ok else 0
                best = max(best, run * (r1 - r0))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_largest_rectangle_is_the_brute_force_one(seed):
    rng = np.random.default_rng(seed)
    # a rotated square footprint, as a UTM grid warped onto a true-north site grid
    nr, nc = 18, 22
    r, c = np.mgrid[0:nr, 0:nc]
    a = np.radians(rng.uniform(0, 40))
    u = (c - nc / 2) * np.cos(a) + (r - nr / 2) * np.sin(a)
    v = -(c - nc / 2) * np.sin(a) + (r - nr / 2) * np.cos(a)
    mask = (np.abs(u) < rng.uniform(5, 10)) & (np.abs(v) < rng.uniform(5, 10))
    r0, r1, c0, c1 = largest_data_rectangle(mask)
    assert mask[r0:r1, c0:c1].all()
    assert (r1 - r0) * (c1 - c0) == brute_rectangle_area(mask)


def test_enclosed_gaps_do_not_shrink_it_and_big_grids_stay_inside():
    mask = np.zeros((30, 30), bool)
    mask[2:28, 3:27] = True
    mask[10:12, 10:14] = False  # a lake
    assert largest_data_rectangle(mask) == (2, 28, 3, 27)
    # the blocked search on a large rotated footprint: inside, within a block of the best
    n = 700
    r, c = np.mgrid[0:n, 0:n]
    a = np.radians(3.0)
    u = (c - n / 2) * np.cos(a) + (r - n / 2) * np.sin(a)
    v = -(c - n / 2) * np.sin(a) + (r - n / 2) * np.cos(a)
    big = (np.abs(u) < 330) & (np.abs(v) < 330)
    r0, r1, c0, c1 = largest_data_rectangle(big)
    assert big[r0:r1, c0:c1].all()
    exact = largest_data_rectangle(big, exact_side=n)
    area = (exact[1] - exact[0]) * (exact[3] - exact[2])
    assert (r1 - r0) * (c1 - c0) >= 0.99 * area
    with pytest.raises(DemError):
        largest_data_rectangle(np.zeros((3, 3), bool))
