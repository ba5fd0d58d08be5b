"""Pointing a head at a ground point, and the sight-line and slew-limit check."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.camera.pointing import aim_check, point_head_at
from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.errors import PoseError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

CENTRED = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
OFF_AXIS = Intrinsics(1000.0, 1004.0, 652.0, 351.25, 1280, 720, k1=-0.1, k2=0.02, p1=3e-4)
HEAD = PanTiltHead([10.0, -20.0, 30.0], 75.0, CENTRED)


def test_a_centred_lens_points_along_the_azimuth_and_elevation():
    p = np.array([110.0, 80.0, 0.0])
    pan, tilt = point_head_at(HEAD, p)
    v = p - HEAD.position_enu
    az = math.degrees(math.atan2(v[0], v[1]))
    el = math.degrees(math.atan2(v[2], math.hypot(v[0], v[1])))
    assert pan == pytest.approx(az - 75.0, abs=1e-12) and tilt == pytest.approx(el, abs=1e-12)
    cam = HEAD.camera_at(pan, tilt)
    np.testing.assert_allclose(cam.R_world_cam[:, 2], v / np.linalg.norm(v), atol=1e-14)


@settings(max_examples=80, deadline=None)
@given(
    e=st.floats(-500, 500),
    n=st.floats(-500, 500),
    u=st.floats(-100, 29),
    hfov=st.one_of(st.none(), st.floats(5.0, 80.0)),
    yaw=st.floats(-180, 180),
)
def test_round_trip_projects_to_the_image_centre(e, n, u, hfov, yaw):
    head = PanTiltHead([10.0, -20.0, 30.0], yaw, OFF_AXIS)
    p = np.array([e, n, u])
    if math.hypot(e - 10.0, n + 20.0) < 5.0:
        return  # nearly straight below: the centre pixel may not reach it within the tilt range
    pan, tilt = point_head_at(head, p, hfov_deg=hfov)
    cam = camera_at(head, PoseSample(0.0, pan, tilt, hfov))
    px, py, front = cam.project(p)
    assert front[0]
    assert px[0] == pytest.approx(639.5, abs=1e-6) and py[0] == pytest.approx(359.5, abs=1e-6)
    assert -180.0 < pan <= 180.0


def ridge_dem():
    """Flat at 0 with a 20 m ridge along N = 100 (E -200 .. 200)."""
    grid = GridSpec(-200.0, 200.0, 1.0, 400, 400)
    z = np.zeros(grid.shape, np.float32)
    rows = np.arange(grid.shape[0])
    north = 200.0 - 0.5 - rows  # row 0 is the northern row
    z[(np.abs(north - 100.0) < 3.0), :] = 20.0
    return Dem(grid, z)


def test_aim_check_clear_blocked_and_limits():
    dem = ridge_dem()
    head = PanTiltHead([0.0, 0.0, 10.0], 0.0, CENTRED)
    near = aim_check(head, [0.0, 50.0], dem)
    assert near.visible and near.reason == "" and near.target_enu[2] == pytest.approx(1.0)
    assert near.distance_m == pytest.approx(math.hypot(50.0, 9.0))
    far = aim_check(head, [0.0, 150.0], dem)
    assert not far.visible and far.blocked_at_m is not None
    # The sight line from 10 m up meets the ridge's south face (N = 97) first.
    assert far.blocked_at_m * math.cos(math.radians(-far.tilt_deg)) == pytest.approx(97.0, abs=1.0)
    assert far.reason.startswith("blocked by terrain") and "\n" not in far.reason
    low = aim_check(head, [0.0, 20.0], dem, slew_limits={"tilt_min_deg": -10.0})
    assert not low.visible and "below the head's tilt limit -10" in low.reason
    side = aim_check(head, [-50.0, 0.0], dem, slew_limits={"pan_min_deg": 0, "pan_max_deg": 300})
    assert side.visible and side.pan_deg == pytest.approx(270.0)
    boxed = aim_check(head, [-50.0, 0.0], dem, slew_limits={"pan_min_deg": -30, "pan_max_deg": 30})
    assert not boxed.visible and "pan limits" in boxed.reason
    off = aim_check(head, [900.0, 0.0], dem)
    assert not off.visible and off.reason == "the point is off the DEM"


def test_bad_points():
    with pytest.raises(PoseError, match="optical centre"):
        point_head_at(HEAD, HEAD.position_enu)
    with pytest.raises(PoseError, match="finite"):
        point_head_at(HEAD, [1.0, math.nan, 0.0])
