from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.site.folder import Sensor
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking.types import TruthPath
from demtrack.core.visibility.handoff import evaluate_handoffs, predict_handoff

INTR = Intrinsics(320.0, 320.0, 319.5, 239.5, 640, 480)  # 90 deg horizontal field of view


def flat(size=200.0, cell=1.0):
    n = int(2 * size / cell)
    grid = GridSpec(-size, size, cell, n, n)
    return Dem(grid, np.zeros(grid.shape, np.float32))


def sensor(sid, x, y, yaw, pan=0.0, tilt=-20.0):
    return Sensor(sid, sid, PanTiltHead([x, y, 15.0], yaw, INTR), pan, tilt)


def two_cameras():
    # A looks north from (-40, -40), B looks north from (+40, -40): their ground footprints
    # are side by side, with a strip near x = 0 seen by neither at y ~ 0.
    return {"A": sensor("A", -40.0, -40.0, 0.0), "B": sensor("B", 40.0, -40.0, 0.0)}


def test_walking_east_passes_from_a_to_b():
    dem, cams = flat(), two_cameras()
    pred = predict_handoff(
        dem, cams, np.array([-40.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0]), height_m=1.7
    )
    assert pred.current == "A" and pred.next_sensor == "B" and not pred.slew
    assert 0 < pred.exit_in_s <= pred.next_in_s < 20
    # Where B picks it up the target is in B's image.
    u, v, front = cams["B"].camera.project((pred.acquisition_enu + [0, 0, 0.85])[None, :])
    assert front[0] and cams["B"].camera.in_image(u, v)[0]


def test_slew_points_the_next_head_at_the_target():
    dem = flat()
    cams = {"A": sensor("A", -40.0, -40.0, 0.0), "B": sensor("B", 40.0, -40.0, 0.0, pan=180.0)}
    pred = predict_handoff(
        dem, cams, np.array([-40.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0]), height_m=1.7
    )
    assert pred.next_sensor == "B" and pred.slew
    cam = cams["B"].head.camera_at(pred.pan_deg, pred.tilt_deg)
    u, v, _ = cam.project((pred.acquisition_enu + [0, 0, 0.85])[None, :])
    assert u[0] == pytest.approx(INTR.cx, abs=1e-6) and v[0] == pytest.approx(INTR.cy, abs=1e-6)


def test_nobody_next_when_walking_out_of_every_cameras_range():
    dem, cams = flat(), two_cameras()
    pred = predict_handoff(
        dem, cams, np.array([-40.0, 0.0, 0.0]), np.array([0.0, 5.0, 0.0]), max_range_m=60.0
    )
    assert pred.current == "A" and pred.next_sensor is None
    # A loses it at about 60 m: sqrt(60^2 - 15^2) - 40 = 18.1 m north, 3.6 s.
    assert pred.exit_in_s == pytest.approx(3.6, abs=0.5)


def test_evaluation_counts_the_truth_handoff_and_scores_it():
    dem, cams = flat(), two_cameras()
    t = np.arange(0.0, 30.0, 0.1)
    truth = TruthPath(
        1, "human", t, np.column_stack([-60.0 + 4.0 * t, np.zeros_like(t), np.zeros_like(t)])
    )
    score = evaluate_handoffs(dem, cams, [truth], height_m=1.7)
    assert score.handoffs == 1 and score.correct == 1 and score.accuracy == 1.0
    assert score.early_s[0] >= 2.0
    assert score.leads_s == pytest.approx((2.0,))


def test_a_handoff_soon_after_takeover_is_scored_from_the_takeover():
    # The walker appears in A's view about 1 s before it leaves it: nobody could predict the
    # hand-off 2 s ahead, so the scored prediction is the first one A can make.
    dem, cams = flat(), two_cameras()
    exit_in = predict_handoff(
        dem, cams, np.array([-40.0, 0.0, 0.0]), np.array([4.0, 0.0, 0.0]), height_m=1.7
    ).exit_in_s
    x_exit = -40.0 + 4.0 * exit_in
    t = np.arange(0.0, 20.0, 0.1)
    truth = TruthPath(
        1, "human", t, np.column_stack([x_exit - 4.0 + 4.0 * t, np.zeros_like(t), np.zeros_like(t)])
    )
    score = evaluate_handoffs(dem, cams, [truth], height_m=1.7, lead_s=2.0)
    assert score.handoffs == 1 and score.correct == 1
    assert 0.0 < score.leads_s[0] < 2.0
    assert score.leads_s[0] == pytest.approx(1.0, abs=0.6)


def test_many_targets_at_once_get_each_ones_own_prediction(sample_site_dir):
    """predict_handoffs (one visibility call per camera and height) equals
    predict_handoff target by target, on the sample site's terrain and roads."""
    from demtrack.core.site.folder import load_site
    from demtrack.core.visibility.handoff import HandoffTarget, predict_handoffs

    site = load_site(sample_site_dir)
    rng = np.random.default_rng(3)
    targets = []
    for k in range(16):
        xy = rng.uniform(-120.0, 120.0, 2)
        z = float(site.dem.sample(xy[:1], xy[1:])[0])
        speed = rng.uniform(0.5, 12.0)
        heading = rng.uniform(0, 2 * np.pi)
        v = np.array([speed * np.sin(heading), speed * np.cos(heading), 0.0])
        current = [None, "cam1", "cam2", "cam3"][k % 4]
        roads = site.roads if k % 2 else None
        targets.append(HandoffTarget(np.array([*xy, z]), v, current, [1.7, 1.5][k % 3 % 2], roads))
    many = predict_handoffs(site.dem, site.sensors, targets, horizon_s=10.0, dt_s=1.0)
    for t, got in zip(targets, many, strict=True):
        one = predict_handoff(
            site.dem,
            site.sensors,
            t.p_enu,
            t.v_enu,
            current=t.current,
            height_m=t.height_m,
            horizon_s=10.0,
            dt_s=1.0,
            roads=t.roads,
        )
        for name in ("current", "exit_in_s", "next_sensor", "next_in_s", "slew", "pan_deg"):
            assert getattr(got, name) == getattr(one, name)
        assert (got.acquisition_enu is None) == (one.acquisition_enu is None)
        if one.acquisition_enu is not None:
            np.testing.assert_array_equal(got.acquisition_enu, one.acquisition_enu)
    assert {p.next_sensor for p in many} - {None}  # some hand-offs among them
    assert predict_handoffs(site.dem, site.sensors, []) == []
