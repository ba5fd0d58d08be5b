"""Gap explanations on hand-built scenes with known geometry."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import TrackingError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking.types import Track, TrackPoint
from demtrack.core.visibility.gap_explain import explain_gap, explain_track_gaps

INTR = Intrinsics(60.0, 60.0, 99.5, 74.5, 200, 150)  # 118 deg wide: |y| < 1.67 x


def scene(kind: str) -> Dem:
    grid = GridSpec(-40.0, 80.0, 1.0, 160, 120)
    x, y = grid.centres()
    if kind == "block":  # an 8 m building, 5 m deep, 12 m wide
        z = np.where((x > 9) & (x < 14) & (np.abs(y) < 6), 8.0, 0.0)
    else:  # a broad 2 m ridge across the whole view
        z = np.maximum(0.0, 2.0 - np.abs(x - 15.0) * 0.1)
    return Dem(grid, z.astype(np.float32))


def north_along(x_m: float):
    """A target walking north along ``x = x_m`` at 1 m/s: y = t - 60."""
    return lambda t: np.column_stack([np.full(len(t), x_m), t - 60.0, np.zeros(len(t))])


def test_block_gives_object_occlusion_missed_and_outside_view():
    dem = scene("block")
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 5.0], 90.0, -5.0, 0.0)
    path = north_along(25.0)
    # Behind the block (|y| < 8): the sight line meets its front face at x ~ 9.
    hidden = explain_gap(dem, {"c1": cam}, path, 52.0, 68.0)
    assert hidden.reason == "occluded" and hidden.shares["occluded"] > 0.9
    assert hidden.occlusions and all(o.kind == "object" for o in hidden.occlusions)
    xs = np.array([o.p_enu[0] for o in hidden.occlusions])
    assert np.all((xs > 8.4) & (xs < 9.6))
    assert all(2.0 < o.above_ground_m <= 8.0 for o in hidden.occlusions)
    # Past the block's shadow (y > 18 at x = 25), still in view (y < 41.6): missed.
    missed = explain_gap(dem, {"c1": cam}, path, 85.0, 90.0)
    assert missed.reason == "missed" and missed.shares["missed"] == 1.0 and not missed.occlusions
    # Far north: outside the image.
    away = explain_gap(dem, {"c1": cam}, path, 108.0, 118.0)
    assert away.reason == "outside-fov" and away.shares["outside-fov"] == 1.0


def test_low_ridge_is_terrain_occlusion():
    dem = scene("ridge")
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 2.0], 90.0, 0.0, 0.0)
    path = lambda t: np.column_stack([np.full(len(t), 30.0), 0.2 * (t - 5), np.zeros(len(t))])  # noqa: E731
    out = explain_gap(dem, {"c1": cam}, path, 0.0, 10.0, height_m=1.5)
    assert out.reason == "occluded"
    assert out.occlusions and all(o.kind == "terrain" for o in out.occlusions)
    # The sight line to the target's middle meets the ridge's near flank, below 2 m.
    assert all(5.0 < o.p_enu[0] <= 15.5 and o.above_ground_m < 2.0 for o in out.occlusions)


def test_second_camera_that_sees_turns_occlusion_into_a_miss():
    dem = scene("block")
    behind = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 5.0], 90.0, -5.0, 0.0)
    side = Camera.from_azimuth_tilt_roll(INTR, [25.0, -30.0, 5.0], 0.0, -5.0, 0.0)
    out = explain_gap(dem, {"a": behind, "b": side}, north_along(25.0), 55.0, 65.0)
    assert out.reason == "missed"


def test_track_gaps_use_the_line_across_the_gap():
    dem = scene("block")
    cam = Camera.from_azimuth_tilt_roll(INTR, [0.0, 0.0, 5.0], 90.0, -5.0, 0.0)
    pts = [TrackPoint(t, np.array([25.0, t - 60.0, 0.0]), ("c1",), (0,)) for t in (40.0, 80.0)]
    track = Track(1, "human", tuple(pts), frozenset({"c1"}), ((50.0, 70.0),))
    (gap,) = explain_track_gaps(dem, {"c1": cam}, track)
    assert gap.reason == "occluded" and gap.t_start_s == 50.0
    doc = gap.to_dict()
    assert doc["blockers"][0]["kind"] == "object" and doc["reason"] == "occluded"
    with pytest.raises(TrackingError, match="gap must end after it starts"):
        explain_gap(dem, {"c1": cam}, north_along(25.0), 5.0, 5.0)
