"""Photogrammetric poses: omega-phi-kappa and rotation matrices in a CRS's grid axes.

Oracles: the OPK definition written out with scipy's rotations, the analytic nadir pose,
:func:`pose_from_survey` (an independent path through azimuth, tilt, roll and PROJ's
meridian convergence) and PROJ's convergence formula on a WGS84-based grid.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from demtrack.core.camera.pinhole import Intrinsics, rotation_from_azimuth_tilt_roll
from demtrack.core.camera.pose import (
    grid_convergence_deg,
    pose_from_rotation,
    pose_from_survey,
    rotation_from_opk_deg,
)
from demtrack.core.errors import CameraError
from demtrack.core.geo.geodesy import LocalFrame, meridian_convergence_deg

FRAME = LocalFrame(40.3, -79.6, 300.0)
INTR = Intrinsics(1000.0, 1000.0, 319.5, 239.5, 640, 480)
UTM17 = "EPSG:32617"
# A camera 600 m east and 400 m north of the anchor, in UTM 17N.
X, Y = 620_000.0, 4_461_000.0


def test_opk_is_rx_ry_rz_with_camera_z_backwards():
    o, p, k = 3.1, -7.4, 123.0
    r = Rotation.from_euler("XYZ", [o, p, k], degrees=True).as_matrix()  # intrinsic = Rx Ry Rz
    np.testing.assert_allclose(rotation_from_opk_deg(o, p, k), r @ np.diag([1, -1, -1]), atol=1e-15)


def test_zero_opk_is_a_nadir_camera_with_the_image_top_north():
    r = rotation_from_opk_deg(0.0, 0.0, 0.0)
    np.testing.assert_array_equal(r[:, 2], [0, 0, -1])  # looks down
    np.testing.assert_array_equal(r[:, 0], [1, 0, 0])  # image right = east
    np.testing.assert_array_equal(-r[:, 1], [0, 1, 0])  # image up = north


def test_utm_grid_convergence_is_the_projection_formula():
    lon, lat = -79.5, 40.3
    from pyproj import Transformer

    x, y = Transformer.from_crs("EPSG:4326", UTM17, always_xy=True).transform(lon, lat)
    assert grid_convergence_deg(UTM17, x, y) == pytest.approx(
        meridian_convergence_deg(UTM17, lat, lon), abs=1e-8
    )
    assert grid_convergence_deg("EPSG:4326", lon, lat) == 0.0


@settings(max_examples=30, deadline=None)
@given(
    az=st.floats(0.0, 360.0),
    tilt=st.floats(-89.0, 30.0),
    roll=st.floats(-20.0, 20.0),
    north=st.sampled_from(["grid", "true"]),
)
def test_a_matrix_pose_is_the_surveyed_pose_with_the_same_angles(az, tilt, roll, north):
    # In the grid axes a rotation built from (az, tilt, roll) means a grid azimuth az: the
    # surveyed pose with north="grid" (PROJ's convergence formula) is the same camera.
    rot = rotation_from_azimuth_tilt_roll(az, tilt, roll)
    a = pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, rot, north=north)
    b = pose_from_survey(FRAME, INTR, X, Y, 350.0, UTM17, az, tilt, roll, north=north)
    np.testing.assert_allclose(a.camera.R_world_cam, b.camera.R_world_cam, atol=1e-9)
    np.testing.assert_array_equal(a.camera.position_enu, b.camera.position_enu)
    assert a.convergence_deg == pytest.approx(b.convergence_deg, abs=1e-8)


def test_grid_is_the_default_for_a_projected_crs_and_true_for_degrees():
    rot = rotation_from_opk_deg(2.0, -5.0, 40.0)
    a = pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, rot)
    assert a.convergence_deg == pytest.approx(0.913, abs=1e-3)  # (lon - lon0) sin(lat)
    b = pose_from_rotation(FRAME, INTR, -79.5, 40.3, 350.0, "EPSG:4979", rot)
    assert b.convergence_deg == 0.0
    with pytest.raises(CameraError, match="geographic"):
        pose_from_rotation(FRAME, INTR, -79.5, 40.3, 350.0, "EPSG:4979", rot, north="grid")


def test_ignoring_the_grid_turns_the_view_by_the_convergence():
    rot = rotation_from_opk_deg(0.0, 30.0, 0.0)  # Ry(30) (0, 0, -1): 30 deg off nadir, west
    g = pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, rot, north="grid")
    t = pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, rot, north="true")
    turn = (g.az_true_deg - t.az_true_deg + 180.0) % 360.0 - 180.0
    assert turn == pytest.approx(g.convergence_deg, abs=1e-9)
    assert math.isclose(t.az_true_deg, 270.0, abs_tol=1e-9)


@pytest.mark.parametrize(
    ("matrix", "match"),
    [
        (np.eye(3) * 1.01, "proper rotation"),
        (np.diag([1.0, 1.0, -1.0]), "proper rotation"),
        (np.full((3, 3), np.nan), "finite 3x3"),
        (np.eye(2), "finite 3x3"),
    ],
)
def test_a_matrix_that_is_not_a_rotation_is_refused(matrix, match):
    with pytest.raises(CameraError, match=match):
        pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, matrix)


def test_a_rounded_export_matrix_is_accepted_and_made_orthonormal():
    rot = np.round(rotation_from_opk_deg(1.0, 2.0, 3.0), 8)
    cam = pose_from_rotation(FRAME, INTR, X, Y, 350.0, UTM17, rot).camera
    assert np.abs(cam.R_world_cam.T @ cam.R_world_cam - np.eye(3)).max() < 1e-12
