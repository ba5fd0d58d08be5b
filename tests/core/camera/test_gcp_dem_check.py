"""The GCP-versus-DEM check on analytic terrain.

Oracles: a flat DEM at z = 0 seen from 50 m up, where a GCP raised by ``dz`` has
``dh = dz`` exactly and its ray meets the plane ``dz / sin(elevation)`` beyond it; a wall
(a step in the DEM) between the camera and a GCP, which blocks the ray before it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demtrack.core.camera.gcp_dem_check import check_gcps_inside_dem, check_gcps_on_dem
from demtrack.core.camera.gcp_io import Gcp
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CalibrationError
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

GRID = GridSpec(-200.0, 400.0, 1.0, 600, 400)  # E -200..200, N -200..400 (cell edges)
CAM = Camera.from_azimuth_tilt_roll(
    Intrinsics(800.0, 800.0, 399.5, 299.5, 800, 600), [0.0, 0.0, 50.0], 0.0, -30.0
)


def gcp(name, e, n, z):
    return Gcp(name, 0.0, 0.0, np.array([e, n, z], float))


@pytest.fixture(scope="module")
def flat():
    return Dem(GRID, np.zeros(GRID.shape, np.float32))


def test_raised_and_sunk_gcps_on_a_plane(flat):
    gcps = [
        gcp("on", 10.0, 100.0, 0.0),
        gcp("up2", -5.0, 80.0, 2.0),
        gcp("down1", 0.0, 120.0, -1.0),
    ]
    chk = check_gcps_on_dem(CAM, gcps, flat)
    assert chk.dh_m == pytest.approx([0.0, 2.0, -1.0], abs=1e-6)
    assert chk.ray == ("reaches", "passes over", "blocked")
    assert chk.flagged.tolist() == [False, True, True]
    assert chk.reasons[0] == ""
    assert "2.00 m above the DEM" in chk.reasons[1] and "ray passes over" in chk.reasons[1]
    assert "1.00 m below the DEM" in chk.reasons[2] and "ray blocked" in chk.reasons[2]
    # On a plane the ray through a point dz above it meets the plane dz / sin(e) beyond.
    d = gcps[1].p_enu - CAM.position_enu
    sin_e = (CAM.position_enu[2] - 2.0) / np.linalg.norm(d)  # the ray is straight
    p_hit = CAM.position_enu + d * (CAM.position_enu[2] / (CAM.position_enu[2] - 2.0))
    want = np.linalg.norm(p_hit - CAM.position_enu) - np.linalg.norm(d)
    assert chk.ray_miss_m[1] == pytest.approx(want, rel=1e-4)
    assert chk.grazing_deg[1] == pytest.approx(math.degrees(math.asin(sin_e)), abs=0.2)


def test_tolerance_and_a_wall_that_blocks_the_ray():
    e, n = GRID.centres()
    z = np.where((n > 60.0) & (n < 64.0), 40.0, 0.0).astype(np.float32)
    dem = Dem(GRID, z)
    chk = check_gcps_on_dem(
        CAM, [gcp("behind wall", 0.0, 150.0, 0.0), gcp("near", 0.0, 40.0, 0.3)], dem
    )
    assert chk.ray[0] == "blocked" and chk.flagged[0] and abs(chk.dh_m[0]) < 1e-6
    assert "ray blocked" in chk.reasons[0] and "height" not in chk.reasons[0]
    # 0.3 m above the terrain is within the default 0.5 m tolerance.
    assert chk.ray[1] == "reaches" and not chk.flagged[1]
    strict = check_gcps_on_dem(CAM, [gcp("near", 0.0, 40.0, 0.3)], dem, height_tol_m=0.1)
    assert strict.flagged[0] and strict.tolerance_m[0] == pytest.approx(0.1)


def test_dem_variance_widens_the_tolerance(flat):
    noisy = Dem(GRID, np.zeros(GRID.shape, np.float32), np.full(GRID.shape, 0.25, np.float32))
    chk = check_gcps_on_dem(CAM, [gcp("g", 0.0, 100.0, 1.2)], noisy)
    assert chk.tolerance_m[0] == pytest.approx(1.5) and not chk.flagged[0]


def test_gcp_outside_the_dem_is_one_line(flat):
    with pytest.raises(CalibrationError, match="'far' at E 0.0 N 900.0 m is outside the DEM") as e:
        check_gcps_inside_dem([gcp("far", 0.0, 900.0, 0.0)], flat)
    assert "\n" not in str(e.value)
