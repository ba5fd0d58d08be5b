"""The detectors' batched steps give the bits of the per-pair / shapely forms they replace."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely
from test_activity_reference import Path, random_scene

from demtrack.core.activity.convoy import _Drive, _project
from demtrack.core.activity.detectors import _resample
from demtrack.core.activity.rendezvous import _ever_close


def _scene(seed: int) -> list[Path]:
    """The reference tests' scene, plus a track with repeated times (a fused track)."""
    paths = random_scene(seed)
    rng = np.random.default_rng(seed + 100)
    t = np.repeat(np.arange(0.0, 90.0, 0.5), 2)
    p = np.column_stack([rng.normal(0, 3, (len(t), 2)).cumsum(axis=0), np.zeros(len(t))])
    paths.append(Path(len(paths) + 1, "human", t, p))
    return paths


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("distance_m", [5.0, 40.0])
def test_ever_close_equals_the_per_pair_test(seed: int, distance_m: float) -> None:
    paths = [p for p in _scene(seed) if len(p.t_s) >= 2]
    pairs, grids = [], []
    for a, b in itertools.combinations(range(len(paths)), 2):
        ta, tb = paths[a].t_s, paths[b].t_s
        lo_t, hi_t = max(ta[0], tb[0]), min(ta[-1], tb[-1])
        grid = np.arange(lo_t, hi_t + 1e-9, 1.0)
        if len(grid):
            pairs.append((a, b))
            grids.append(grid)
    want = [
        bool(
            (
                np.hypot(*(_resample(paths[a], g, 2) - _resample(paths[b], g, 2)).T) <= distance_m
            ).any()
        )
        for (a, b), g in zip(pairs, grids, strict=True)
    ]
    got = _ever_close(paths, pairs, grids, distance_m)
    assert got.tolist() == want
    assert any(want) and not all(want)  # both answers are exercised
    assert _ever_close(paths, [], [], distance_m).shape == (0,)


@pytest.mark.parametrize("seed", range(4))
def test_project_gives_shapely_bits(seed: int) -> None:
    """What the convoy test read from shapely: distance to and located length on a path."""
    paths = [p for p in _scene(seed) if len(p.t_s) >= 2]
    xy = np.concatenate([p.p_enu[:, :2] for p in paths])
    for leader in paths:
        drive = _Drive.of(leader)
        line = shapely.LineString(drive.p[:, :2])
        pts = shapely.points(xy[:, 0], xy[:, 1])
        dist, along = _project(drive, xy)
        np.testing.assert_array_equal(dist, shapely.distance(pts, line))
        np.testing.assert_array_equal(along, shapely.line_locate_point(line, pts))
    empty = _project(_Drive.of(paths[0]), np.zeros((0, 2)))
    assert empty[0].shape == empty[1].shape == (0,)


@pytest.mark.parametrize("n", [2, 3, 50])
@pytest.mark.parametrize("dt", [0.5, 1.0, 0.1, 3])
def test_speed_equals_np_gradient(n: int, dt: float) -> None:
    """``_speed`` writes out ``np.gradient`` (uniform spacing, first-order edges)."""
    from demtrack.core.activity.detectors import _speed

    p = np.random.default_rng(n).normal(0, 50, (n, 3))
    v = np.gradient(p[:, :2], dt, axis=0)
    np.testing.assert_array_equal(_speed(p, dt), np.hypot(v[:, 0], v[:, 1]))
    assert _speed(p[:1], dt).tolist() == [0.0]
