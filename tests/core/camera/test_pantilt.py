from __future__ import annotations

import json
import math

import numpy as np
import pytest

from demtrack.core.camera.pantilt import (
    LandmarkReading,
    PanTiltHead,
    calibrate_mount_yaw,
    wrap_deg,
)
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.errors import CalibrationError, CameraError

INTR = Intrinsics(1200.0, 1200.0, 639.5, 359.5, 1280, 720, k1=-0.1, k2=0.02)
HEAD_ENU = np.array([120.0, -40.0, 312.5])


def bearings_deg(landmarks, head=HEAD_ENU):
    """Independent bearing: the azimuth of a horizontal vector, via complex numbers."""
    d = np.asarray(landmarks)[:, :2] - head[:2]
    # Clockwise from north: the angle of (north + i east).
    return np.degrees(np.angle(d[:, 1] + 1j * d[:, 0]))


def ring_of_landmarks(rng, k):
    az = rng.uniform(0, 360, k)
    dist = rng.uniform(50, 2000, k)
    return np.column_stack(
        [
            HEAD_ENU[0] + dist * np.sin(np.radians(az)),
            HEAD_ENU[1] + dist * np.cos(np.radians(az)),
            HEAD_ENU[2] + rng.uniform(-30, 30, k),
        ]
    )


def test_wrap_deg_half_open_interval():
    got = wrap_deg([180.0, -180.0, 540.0, 190.0, -190.0, 0.0, 359.5, -0.0, 720.0])
    np.testing.assert_array_equal(got, [180.0, 180.0, 180.0, -170.0, 170.0, 0.0, -0.5, 0.0, 0.0])


@pytest.mark.parametrize(
    ("yaw", "pan", "tilt"),
    [(0.0, 0.0, 0.0), (30.0, 60.0, -10.0), (350.0, 25.0, 5.0), (-100.0, -100.0, -45.0)],
)
def test_camera_at_azimuth_is_mount_yaw_plus_pan(yaw, pan, tilt):
    head = PanTiltHead(HEAD_ENU, yaw, INTR)
    cam = head.camera_at(pan, tilt)
    az, el = math.radians(yaw + pan), math.radians(tilt)
    forward = [math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)]
    np.testing.assert_allclose(cam.R_world_cam[:, 2], forward, atol=1e-15)
    assert cam.R_world_cam[2, 0] == pytest.approx(0.0, abs=1e-15)  # levelled: no roll
    np.testing.assert_array_equal(cam.position_enu, HEAD_ENU)
    a, t, r = cam.azimuth_tilt_roll_deg()
    assert wrap_deg(a - (yaw + pan)) == pytest.approx(0.0, abs=1e-9)
    assert (t, r) == pytest.approx((tilt, 0.0), abs=1e-9)


def test_recovers_known_yaw_from_noisy_pans():
    rng = np.random.default_rng(0)
    yaw_true, sigma, k = 37.5, 0.05, 12
    lm = ring_of_landmarks(rng, k)
    pans = wrap_deg(bearings_deg(lm) - yaw_true + rng.normal(0, sigma, k))
    cal = calibrate_mount_yaw(HEAD_ENU, lm, pans)
    assert abs(cal.yaw_deg - yaw_true) < 4 * sigma / math.sqrt(k)
    np.testing.assert_allclose(cal.bearings_deg, bearings_deg(lm), atol=1e-12)
    np.testing.assert_allclose(cal.yaws_deg, wrap_deg(bearings_deg(lm) - pans), atol=1e-12)
    np.testing.assert_allclose(cal.residuals_deg, cal.yaws_deg - cal.yaw_deg, atol=1e-12)
    assert cal.rms_deg == pytest.approx(np.sqrt(np.mean(cal.residuals_deg**2)))
    assert 0.5 * sigma < cal.rms_deg < 2 * sigma
    assert not cal.outliers.any() and cal.warnings == ()
    np.testing.assert_allclose(cal.distances_m, np.hypot(*(lm[:, :2] - HEAD_ENU[:2]).T))
    # Only east and north matter.
    cal2 = calibrate_mount_yaw(HEAD_ENU[:2], lm[:, :2], pans)
    assert cal2.yaw_deg == cal.yaw_deg


@pytest.mark.parametrize("yaw_true", [179.95, -179.95, 180.0])
def test_circular_mean_near_180_where_arithmetic_mean_fails(yaw_true):
    rng = np.random.default_rng(0)
    sigma, k = 0.1, 10
    lm = ring_of_landmarks(rng, k)
    pans = bearings_deg(lm) - yaw_true + rng.normal(0, sigma, k)
    cal = calibrate_mount_yaw(HEAD_ENU, lm, pans)
    # The per-landmark yaws straddle the +-180 seam ...
    assert (cal.yaws_deg > 0).any() and (cal.yaws_deg < 0).any()
    # ... so their arithmetic mean is tens of degrees off, the circular mean is right.
    assert abs(wrap_deg(np.mean(cal.yaws_deg) - yaw_true)) > 10.0
    assert abs(wrap_deg(cal.yaw_deg - yaw_true)) < 4 * sigma / math.sqrt(k)
    assert -180.0 < cal.yaw_deg <= 180.0
    assert np.abs(cal.residuals_deg).max() < 5 * sigma  # residuals wrapped, not ~360


def test_analytic_residuals_symmetric():
    # Landmarks due north, east and south; pans giving yaws 9, 10 and 11 degrees.
    lm = HEAD_ENU[:2] + np.array([[0.0, 100.0], [250.0, 0.0], [0.0, -30.0]])
    pans = np.array([0.0 - 9.0, 90.0 - 10.0, 180.0 - 11.0])
    cal = calibrate_mount_yaw(HEAD_ENU, lm, pans, names=["n", "e", "s"])
    assert cal.yaw_deg == pytest.approx(10.0, abs=1e-12)
    np.testing.assert_allclose(cal.residuals_deg, [-1.0, 0.0, 1.0], atol=1e-12)
    assert cal.rms_deg == pytest.approx(math.sqrt(2 / 3), abs=1e-12)


def test_analytic_residuals_asymmetric_and_outlier_flagged_not_dropped():
    # Yaws 0, 0, 90: circular mean atan2(sin sum, cos sum) = atan2(1, 2).
    lm = HEAD_ENU[:2] + np.array([[0.0, 10.0], [10.0, 0.0], [-10.0, 0.0]])
    pans = np.array([0.0, 90.0, -90.0 - 90.0])
    cal = calibrate_mount_yaw(
        HEAD_ENU, lm, pans, outlier_threshold_deg=30.0, names=["a", "b", "c"], reject_outliers=False
    )
    mean = math.degrees(math.atan2(1.0, 2.0))
    np.testing.assert_allclose(cal.yaws_deg, [0.0, 0.0, 90.0], atol=1e-12)
    assert cal.yaw_deg == pytest.approx(mean, abs=1e-12)
    np.testing.assert_allclose(cal.residuals_deg, [-mean, -mean, 90.0 - mean], atol=1e-12)
    np.testing.assert_array_equal(cal.outliers, [False, False, True])
    assert len(cal.residuals_deg) == 3
    assert len(cal.warnings) == 1 and "landmark c" in cal.warnings[0]


def test_matches_papers_math_convention_formula():
    # Collins et al.: yaw = atan2(y - y0, x - x0) - pan, angles counter-clockwise from east
    # with a counter-clockwise pan. Ours is its image under az = 90 - theta.
    rng = np.random.default_rng(3)
    lm = ring_of_landmarks(rng, 6)
    pans_cw = rng.uniform(-180, 180, 6)
    ours = calibrate_mount_yaw(HEAD_ENU, lm, pans_cw).yaws_deg
    d = lm[:, :2] - HEAD_ENU[:2]
    paper = np.degrees(np.arctan2(d[:, 1], d[:, 0])) - (-pans_cw)
    np.testing.assert_allclose(wrap_deg(ours - (90.0 - paper)), 0.0, atol=1e-9)


def test_single_landmark_is_exact_but_warned():
    cal = calibrate_mount_yaw(HEAD_ENU, [[HEAD_ENU[0] + 5.0, HEAD_ENU[1] + 5.0]], [15.0])
    assert cal.yaw_deg == pytest.approx(30.0, abs=1e-12)
    assert cal.rms_deg == 0.0 and "single landmark" in cal.warnings[0]


@pytest.mark.parametrize(
    ("lm", "pans", "match"),
    [
        (np.zeros((0, 2)), np.zeros(0), "at least one"),
        ([[120.0, -40.0 + 1e-7, 0.0], [0.0, 0.0, 0.0]], [0.0, 0.0], "head's position"),
        ([[0.0, 0.0]], [0.0, 1.0], "pans_deg"),
        ([[0.0, np.nan]], [0.0], "finite"),
        ([[0.0, 0.0, 0.0, 0.0]], [0.0], "shape"),
        ([[120.0, 0.0], [120.0, -80.0]], [0.0, 0.0], "undefined"),  # yaws 0 and 180
    ],
)
def test_calibration_rejects_bad_input(lm, pans, match):
    with pytest.raises(CalibrationError, match=match):
        calibrate_mount_yaw(HEAD_ENU, lm, pans)


def test_head_calibrates_from_its_readings_and_points_at_landmarks():
    rng = np.random.default_rng(7)
    yaw_true = -123.4
    lm = ring_of_landmarks(rng, 5)
    pans = bearings_deg(lm) - yaw_true
    readings = tuple(
        LandmarkReading(f"L{i}", e, n, p, u)
        for i, ((e, n, u), p) in enumerate(zip(lm, pans, strict=True))
    )
    head = PanTiltHead(HEAD_ENU, 0.0, INTR, readings)
    cal = head.calibrate()
    assert cal.yaw_deg == pytest.approx(yaw_true, abs=1e-9)
    fixed = head.with_mount_yaw(cal.yaw_deg)
    for r in readings:
        tilt = math.degrees(
            math.atan2(r.u - HEAD_ENU[2], math.hypot(r.e - HEAD_ENU[0], r.n - HEAD_ENU[1]))
        )
        u, v, front = fixed.camera_at(r.pan_deg, tilt).project([r.e, r.n, r.u])
        assert front[0]
        assert (u[0], v[0]) == pytest.approx((INTR.cx, INTR.cy), abs=1e-6)
    with pytest.raises(CalibrationError):
        PanTiltHead(HEAD_ENU, 0.0, INTR).calibrate()


def test_head_to_dict_round_trips_through_json():
    readings = (
        LandmarkReading("water tower", 500.0, 800.0, 12.5, 340.0),
        LandmarkReading("chimney", -300.0, 20.0, -95.25),
    )
    head = PanTiltHead(HEAD_ENU, 271.75, INTR, readings)
    doc = json.loads(json.dumps(head.to_dict()))
    assert doc["format"] == "demtrack.pantilt" and doc["version"] == 1
    assert doc["landmarks"][0] == {
        "name": "water tower",
        "e": 500.0,
        "n": 800.0,
        "u": 340.0,
        "pan_deg": 12.5,
    }
    assert "u" not in doc["landmarks"][1]
    assert PanTiltHead.from_dict(doc) == head
    del doc["landmarks"]
    assert PanTiltHead.from_dict(doc).landmarks == ()


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d.update(format="demtrack.camera"),
        lambda d: d.update(version=0),
        lambda d: d.pop("mount_yaw_deg"),
        lambda d: d.update(mount_yaw_deg="north"),
        lambda d: d.update(position_enu=[1.0, 2.0]),
        lambda d: d.update(landmarks={"name": "x"}),
    ],
)
def test_head_from_dict_rejects_malformed(change):
    doc = PanTiltHead(HEAD_ENU, 10.0, INTR).to_dict()
    change(doc)
    with pytest.raises(CameraError):
        PanTiltHead.from_dict(doc)


@pytest.mark.parametrize(
    "reading",
    [
        {"name": "a", "e": 1.0, "n": 2.0},  # no pan
        {"name": "a", "e": 1.0, "n": 2.0, "pan_deg": 3.0, "z": 4.0},  # unknown key
        {"name": "a", "e": "x", "n": 2.0, "pan_deg": 3.0},
        {"name": "a", "e": 1.0, "n": 2.0, "pan_deg": float("inf")},
    ],
)
def test_landmark_reading_rejects_malformed(reading):
    with pytest.raises(CalibrationError):
        LandmarkReading.from_dict(reading)


def test_blunder_is_excluded_from_the_yaw_when_rejecting():
    rng = np.random.default_rng(5)
    lm = ring_of_landmarks(rng, 8)
    d = lm[:, :2] - HEAD_ENU[:2]
    pans = wrap_deg(np.degrees(np.arctan2(d[:, 0], d[:, 1])) - 37.0)
    pans[3] += 2.0  # a misread pan
    plain = calibrate_mount_yaw(HEAD_ENU, lm, pans, reject_outliers=False)
    robust = calibrate_mount_yaw(HEAD_ENU, lm, pans)
    assert plain.yaw_deg == pytest.approx(37.0 - 2.0 / 8, abs=1e-3)  # dragged by blunder / k
    assert robust.yaw_deg == pytest.approx(37.0, abs=1e-9)
    assert robust.outliers.tolist() == [i == 3 for i in range(8)]
    assert robust.rms_deg == pytest.approx(0.0, abs=1e-9)
    assert "excluded" in robust.warnings[0]
