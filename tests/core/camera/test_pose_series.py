"""Pose series: interpolation oracles, the gap rule, latency, and cameras at a pose."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from demtrack.core.camera.attitude import (
    quat_from_rotation,
    rotation_from_quat,
    rotations_from_azimuth_tilt_roll,
    rotations_from_ypr,
    slerp,
    ypr_from_rotation,
)
from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics, rotation_from_azimuth_tilt_roll
from demtrack.core.camera.pose_series import PoseSample, PoseSeries, camera_at
from demtrack.core.camera.zoom_lens import intrinsics_for_hfov
from demtrack.core.errors import CameraError, PoseError

T0 = 1.8e9  # a 2027 clock: nothing treats a time as small
INTR = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720, k1=-0.05)
HEAD = PanTiltHead([100.0, -50.0, 320.0], 30.0, INTR)


def straight(n=11, dt=0.1):
    """Pan, tilt, hfov, roll, position all linear in time."""
    t = T0 + dt * np.arange(n)
    s = t - T0
    return PoseSeries.from_arrays(
        t,
        10.0 + 20.0 * s,
        -5.0 - 3.0 * s,
        hfov_deg=40.0 - 10.0 * s,
        roll_deg=0.5 * s,
        position_enu=np.column_stack([1.0 + 2 * s, 3.0 - s, 300 + 0.1 * s]),
    )


def test_linear_on_a_straight_series_and_exact_at_samples():
    series = straight()
    q = T0 + np.array([0.0, 0.05, 0.137, 0.5, 0.999, 1.0])
    b = series.at(q)
    s = q - T0
    assert b.ok.all()
    np.testing.assert_allclose(b.pan_deg, 10 + 20 * s, atol=1e-9)
    np.testing.assert_allclose(b.tilt_deg, -5 - 3 * s, atol=1e-9)
    np.testing.assert_allclose(b.hfov_deg, 40 - 10 * s, atol=1e-9)
    np.testing.assert_allclose(b.roll_deg, 0.5 * s, atol=1e-9)
    np.testing.assert_allclose(b.position_enu[:, 0], 1 + 2 * s, atol=1e-9)
    # At the samples' own times: the samples, bit for bit.
    exact = series.at(series.t_s)
    np.testing.assert_array_equal(exact.pan_deg, [p.pan_deg for p in series.samples()])
    np.testing.assert_array_equal(exact.hfov_deg, [p.hfov_deg for p in series.samples()])


def test_pan_interpolates_the_short_way_across_180():
    series = PoseSeries.from_arrays([T0, T0 + 0.2], [170.0, -170.0], [0.0, 0.0])
    b = series.at([T0 + 0.05, T0 + 0.1, T0 + 0.15])
    np.testing.assert_allclose(b.pan_deg, [175.0, 180.0, 185.0])
    # The other way round, and an unwrapped reading comes back as it was given.
    series = PoseSeries.from_arrays([T0, T0 + 0.2], [-170.0, 190.0], [0.0, 0.0])
    np.testing.assert_allclose(series.at([T0 + 0.1]).pan_deg, [-170.0])
    np.testing.assert_array_equal(series.at([T0 + 0.2]).pan_deg, [190.0])


def test_platform_attitude_is_slerped_as_scipy_does():
    rng = np.random.default_rng(0)
    n = 6
    t = T0 + 0.1 * np.arange(n)
    ypr = np.column_stack(
        [rng.uniform(-180, 180, n), rng.uniform(-60, 60, n), rng.uniform(-60, 60, n)]
    )
    series = PoseSeries.from_arrays(t, np.zeros(n), np.zeros(n), platform_ypr_deg=ypr)
    q = np.sort(rng.uniform(t[0], t[-1], 40))
    b = series.at(q)
    # The reference: scipy's rotations from the same Euler sequence, slerped by scipy.
    rots = Rotation.from_euler("ZXY", np.column_stack([-ypr[:, 0], ypr[:, 1], ypr[:, 2]]), True)
    ref = Slerp(t - T0, rots)(q - T0).as_matrix()
    np.testing.assert_allclose(b.platform_R_world_body, ref, atol=1e-12)


def test_slerp_and_quaternions_against_scipy():
    rng = np.random.default_rng(1)
    r = Rotation.random(50, random_state=2)
    q = quat_from_rotation(r.as_matrix())
    np.testing.assert_allclose(rotation_from_quat(q), r.as_matrix(), atol=1e-14)
    xyzw = r.as_quat()
    ref = np.column_stack([xyzw[:, 3], xyzw[:, :3]])
    ref *= np.sign(ref[:, :1])
    np.testing.assert_allclose(q, ref, atol=1e-14)
    a = rng.uniform(0, 1, 49)
    got = rotation_from_quat(slerp(q[:-1], q[1:], a))
    for i in range(49):
        want = Slerp([0.0, 1.0], r[i : i + 2])([a[i]]).as_matrix()[0]
        np.testing.assert_allclose(got[i], want, atol=1e-12)


def test_batched_rotations_are_the_scalar_ones():
    rng = np.random.default_rng(5)
    az, tilt, roll = (
        rng.uniform(-400, 400, 40),
        rng.uniform(-90, 90, 40),
        rng.uniform(-180, 180, 40),
    )
    got = rotations_from_azimuth_tilt_roll(az, tilt, roll)
    for k in range(40):
        want = rotation_from_azimuth_tilt_roll(az[k], tilt[k], roll[k])
        np.testing.assert_allclose(got[k], want, atol=2e-16 * 8)


def test_ypr_round_trip_and_its_meaning():
    rng = np.random.default_rng(3)
    ypr = np.column_stack(
        [rng.uniform(-179, 179, 30), rng.uniform(-89, 89, 30), rng.uniform(-179, 179, 30)]
    )
    np.testing.assert_allclose(ypr_from_rotation(rotations_from_ypr(ypr)), ypr, atol=1e-9)
    # yaw 90 (nose east), pitch 10 (nose up), roll 20 (right wing down).
    r = rotations_from_ypr([[90.0, 10.0, 20.0]])[0]
    nose, wing = r[:, 1], r[:, 0]
    assert math.degrees(math.atan2(nose[0], nose[1])) == pytest.approx(90.0)
    assert math.degrees(math.asin(nose[2])) == pytest.approx(10.0)
    assert wing[2] == pytest.approx(-math.cos(math.radians(10.0)) * math.sin(math.radians(20.0)))


@pytest.mark.parametrize(
    ("offset_s", "ok"),
    [
        (-0.2, True),  # before the first sample by the gap exactly
        (-0.2000005, True),  # within the 1 us tolerance
        (-0.2001, False),
        (0.0, True),
        (0.2, True),  # in a 1-s hole, 0.2 s after its start
        (0.5, False),  # in the middle of the hole: no sample close enough
        (0.8, True),
        (1.0, True),
        (1.2, True),  # beyond the end by the gap
        (1.21, False),
    ],
)
def test_the_gap_rule(offset_s, ok):
    series = PoseSeries.from_arrays([T0, T0 + 1.0], [0.0, 10.0], [0.0, -10.0])
    b = series.at([T0 + offset_s])
    assert bool(b.ok[0]) is ok
    if ok:
        want = 10.0 * min(max(offset_s, 0.0), 1.0)  # linear inside, held beyond the ends
        assert b.pan_deg[0] == pytest.approx(want, abs=1e-5)
    else:
        assert np.isnan(b.pan_deg[0]) and np.isnan(b.position_enu[0]).all()
        assert b.sample(0) is None


def test_an_empty_series_has_no_pose_and_the_gap_is_configurable():
    assert not PoseSeries.from_samples([]).at([T0, T0 + 1]).ok.any()
    series = PoseSeries.from_arrays([T0, T0 + 1.0], [0.0, 10.0], [0.0, 0.0])
    assert series.at([T0 + 0.5], max_gap_s=0.5).ok[0]
    assert not series.at([T0 + 0.5], max_gap_s=0.4).ok[0]
    with pytest.raises(PoseError, match="max_gap_s"):
        series.at([T0], max_gap_s=-1)


def test_latency_shifts_the_query():
    series = straight()
    # Telemetry stamps late by 80 ms: the frame at t is read from the series at t + 0.08.
    b = series.at([T0 + 0.3], latency_s=0.08)
    assert b.pan_deg[0] == pytest.approx(10 + 20 * 0.38)
    assert b.t_s[0] == T0 + 0.3  # the batch keeps the video time
    # Shifted past the end by more than the gap: no pose.
    assert not series.at([T0 + 1.0], latency_s=0.3).ok[0]
    assert series.at([T0 - 0.25], latency_s=0.25).ok[0]


@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(st.floats(1e-3, 5.0), min_size=1, max_size=12),
    pans=st.lists(st.floats(-720, 720), min_size=13, max_size=13),
    tilts=st.lists(st.floats(-90, 90), min_size=13, max_size=13),
)
def test_property_at_own_times_returns_the_samples(steps, pans, tilts):
    t = T0 + np.concatenate([[0.0], np.cumsum(steps)])
    n = len(t)
    series = PoseSeries.from_arrays(t, pans[:n], tilts[:n], hfov_deg=np.linspace(5, 60, n))
    b = series.at(series.t_s, max_gap_s=0.0)
    assert b.ok.all()
    samples = series.samples()
    for i in range(n):
        assert b.sample(i) == samples[i]


def test_extended_and_since():
    series = straight(5)
    more = straight(11).samples()[5:]
    longer = series.extended(more)
    assert len(longer) == 11 and longer.samples() == straight(11).samples()
    with pytest.raises(PoseError, match="not after"):
        longer.extended(more[:1])
    with pytest.raises(PoseError, match="differ in zoom"):
        series.extended([PoseSample(T0 + 9, 0.0, 0.0)])
    cut = longer.since(T0 + 0.55)
    assert cut.t_s[0] == longer.t_s[5]
    q = T0 + np.array([0.55, 0.73, 1.0])
    np.testing.assert_array_equal(cut.at(q).pan_deg, longer.at(q).pan_deg)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pan_deg": math.nan}, "pan_deg must be finite"),
        ({"tilt_deg": 91.0}, "tilt_deg"),
        ({"hfov_deg": 0.0}, "hfov_deg"),
        ({"hfov_deg": 180.0}, "hfov_deg"),
        ({"position_enu": (1.0, 2.0)}, "position_enu"),
        ({"platform_ypr_deg": (1.0, math.inf, 0.0)}, "platform_ypr_deg"),
        ({"t_s": "soon"}, "t_s must be a number"),
    ],
)
def test_sample_validation(kwargs, match):
    args = {"t_s": T0, "pan_deg": 0.0, "tilt_deg": 0.0, **kwargs}
    with pytest.raises(PoseError, match=match):
        PoseSample(**args)
    assert issubclass(PoseError, CameraError)


def test_series_validation():
    with pytest.raises(PoseError, match="increase strictly"):
        PoseSeries.from_arrays([T0, T0], [0, 0], [0, 0])
    with pytest.raises(PoseError, match="some samples but not all"):
        PoseSeries.from_samples([PoseSample(T0, 0, 0, 30.0), PoseSample(T0 + 1, 0, 0)])
    with pytest.raises(PoseError, match="shape"):
        PoseSeries.from_arrays([T0, T0 + 1], [0], [0, 0])
    with pytest.raises(PoseError, match="not finite"):
        PoseSeries.from_arrays([T0, T0 + 1], [0, math.nan], [0, 0])


@pytest.mark.parametrize(("pan", "tilt"), [(0.0, 0.0), (25.0, -12.0), (-150.0, 40.0)])
def test_camera_at_is_the_heads_camera_for_a_plain_pose(pan, tilt):
    got = camera_at(HEAD, PoseSample(T0, pan, tilt))
    assert got == HEAD.camera_at(pan, tilt)
    b = PoseSeries.from_samples([PoseSample(T0, pan, tilt)]).at([T0], head=HEAD)
    np.testing.assert_allclose(b.R_world_cam[0], got.R_world_cam, atol=1e-14)
    np.testing.assert_array_equal(b.positions(HEAD)[0], HEAD.position_enu)


def test_camera_at_zoom_roll_and_position():
    pose = PoseSample(T0, 10.0, -5.0, hfov_deg=20.0, roll_deg=3.0, position_enu=(1.0, 2.0, 3.0))
    cam = camera_at(HEAD, pose)
    assert cam.intrinsics == intrinsics_for_hfov(INTR, 20.0)
    np.testing.assert_array_equal(cam.position_enu, [1.0, 2.0, 3.0])
    az, tilt, roll = cam.azimuth_tilt_roll_deg()
    assert (az, tilt, roll) == pytest.approx((40.0, -5.0, 3.0))


def test_camera_at_on_a_moving_platform_against_scipy():
    ypr = (250.0, 8.0, -15.0)
    pose = PoseSample(T0, 35.0, -20.0, roll_deg=2.0, platform_ypr_deg=ypr)
    cam = camera_at(HEAD, pose)
    # Independent: scipy's intrinsic z-x'-y'' platform rotation, then the head's joints
    # as rotations of the body frame: pan clockwise about body up, tilt about the
    # panned right axis, roll about the optical axis; OpenCV axes from (right, fwd, up).
    platform = Rotation.from_euler("ZXY", [-ypr[0], ypr[1], ypr[2]], degrees=True)
    joints = Rotation.from_euler("ZXY", [-(HEAD.mount_yaw_deg + 35.0), -20.0, 2.0], degrees=True)
    opencv_from_rfu = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T  # x, y=-up, z=fwd
    want = (platform * joints).as_matrix() @ opencv_from_rfu
    np.testing.assert_allclose(cam.R_world_cam, want, atol=1e-12)
    b = PoseSeries.from_samples([pose]).at([T0], head=HEAD)
    np.testing.assert_allclose(b.R_world_cam[0], want, atol=1e-12)
    # A levelled platform facing north is the fixed mount.
    level = camera_at(HEAD, PoseSample(T0, 35.0, -20.0, platform_ypr_deg=(0.0, 0.0, 0.0)))
    np.testing.assert_allclose(level.R_world_cam, HEAD.camera_at(35.0, -20.0).R_world_cam)
