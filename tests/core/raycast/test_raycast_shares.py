"""The per-batch passes split over threads give the answers of one serial scan.

``check_rays_kernel`` and ``origin_runs_kernel`` cut a batch into one contiguous share per
thread; whatever the number of shares, the first problem found and the runs of one origin
must be those of a plain scan in ray order (runs cut by a seam are joined again).
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.raycast import _angular_kernels as ak
from demtrack.core.raycast import _ray_kernels as rk

SHARES = (1, 2, 3, 7)


def runs_reference(origins: np.ndarray, min_run: int) -> np.ndarray:
    out, a, n = [], 0, len(origins)
    while a < n:
        b = a + 1
        while b < n and np.array_equal(origins[b], origins[a]):
            b += 1
        if b - a >= min_run:
            out.append((a, b))
        a = b
    return np.array(out, np.int64).reshape(-1, 2)


def first_problem_reference(o: np.ndarray, d: np.ndarray, r: np.ndarray) -> tuple[int, int]:
    for i in range(len(o)):
        if not np.isfinite(o[i]).all():
            return 1, i
        if not np.isfinite(d[i]).all():
            return 2, i
        if not (d[i] ** 2).sum() > 0:
            return 3, i
        if not r[i] >= 0:
            return 4, i
    return 0, -1


@pytest.mark.parametrize("seed", range(40))
def test_origin_runs_are_those_of_a_serial_scan_for_any_share_count(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 80))
    labels = rng.integers(0, int(rng.integers(1, 5)), n)
    if seed % 2:
        labels = np.sort(labels)  # long runs that cross the seams
    origins = np.column_stack([labels, labels * 2.0, np.zeros(n)]).astype(np.float64)
    origins[labels == 1, 2] = -0.0  # equal to 0.0: the same origin, as == says
    min_run = int(rng.integers(1, 7))
    want = runs_reference(origins, min_run)
    for nt in SHARES:
        np.testing.assert_array_equal(ak.origin_runs_kernel(origins, min_run, nt), want)


def test_a_run_spanning_every_share_is_one_run():
    origins = np.tile([1.0, 2.0, 3.0], (50, 1))
    for nt in SHARES:
        np.testing.assert_array_equal(ak.origin_runs_kernel(origins, 20, nt), [[0, 50]])


@pytest.mark.parametrize("seed", range(30))
def test_the_first_problem_is_found_whatever_the_shares(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 60))
    o = rng.normal(size=(n, 3))
    d = rng.normal(size=(n, 3))
    r = rng.uniform(0, 10, n)
    for _ in range(int(rng.integers(0, 4))):
        i = int(rng.integers(0, n))
        kind = int(rng.integers(0, 4))
        if kind == 0:
            o[i, int(rng.integers(0, 3))] = np.inf
        elif kind == 1:
            d[i, int(rng.integers(0, 3))] = np.nan
        elif kind == 2:
            d[i] = 0.0
        else:
            r[i] = -1.0
    want = first_problem_reference(o, d, r)
    for nt in SHARES:
        assert tuple(rk.check_rays_kernel(o, d, r, nt)) == want
