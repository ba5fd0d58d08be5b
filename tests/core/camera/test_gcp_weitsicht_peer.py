"""GCP calibration on real material against two peers: weitsicht's camera and OpenCV.

Material: weitsicht's ``tennis_court_dem01`` case (``weitsicht_tennis.py``): a real
bundle-adjusted camera and the peer's own ground points for 42 pixels on a real DEM. Those
pixel <-> ground pairs are GCPs. The start camera is perturbed (1.7 deg of rotation, 8 m of
position, 3 % of focal length), the pixels get 0.5 px Gaussian noise (seed 0).

Oracles:

* OpenCV on the same GCPs with the same free parameters: ``cv2.solvePnP``
  (``SOLVEPNP_ITERATIVE``) for the pose, ``cv2.calibrateCamera`` with
  ``CALIB_USE_INTRINSIC_GUESS`` and the matching ``CALIB_FIX_*`` flags for intrinsics and
  pose. demtrack's reprojection RMSE must be no worse (to 1e-3 px).
* weitsicht's camera (converted into the site frame through the CRS): the fit recovers it.
  The peer works in MGA grid coordinates as if they were Cartesian; the site frame is exact
  ENU, where horizontal distances are the grid's divided by the grid scale factor ``k``
  (0.9997 here). So a fit with fixed position finds ``fx * k``, not ``fx``: about 3.9 px
  less, and the test expects exactly that (from PROJ's scale factor), not zero.
* Leave-one-out horizontal ground errors no worse than the peer's camera gives for the
  same pixels on the same DEM.
* Outliers: three GCPs moved by 30 px are flagged as reprojection outliers, three whose
  height is raised 1-3 m above the DEM are flagged by the DEM check ("above the DEM", the
  ray passes over them), and no other.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from pyproj import Proj, Transformer
from scipy.spatial.transform import Rotation
from weitsicht_tennis import CRS, DATA, available, load_tennis, rotation_error_deg

from demtrack.core.camera.gcp_calibration import fit_camera_to_gcps
from demtrack.core.camera.gcp_dem_check import check_gcps_on_dem
from demtrack.core.camera.gcp_io import Gcp
from demtrack.core.camera.gcp_loo import leave_one_out
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.raycast.cast import cast_rays

pytestmark = pytest.mark.skipif(not available(), reason="weitsicht data not on this machine")


@pytest.fixture(scope="module")
def case():
    return load_tennis()


@pytest.fixture(scope="module")
def noisy(case):
    rng = np.random.default_rng(0)
    n = rng.normal(0, 0.5, (len(case.gcps), 2))
    return [
        Gcp(g.name, g.u + du, g.v + dv, g.p_enu) for g, (du, dv) in zip(case.gcps, n, strict=True)
    ]


def start(case, intr=None, move_m=(4.0, -3.0, 6.0)):
    turn = Rotation.from_rotvec(np.radians([1.0, -0.8, 1.2])).as_matrix()
    return Camera(
        intr or case.camera.intrinsics,
        case.camera.position_enu + np.asarray(move_m),
        turn @ case.camera.R_world_cam,
    )


def scaled(intr: Intrinsics, s: float = 1.0, dc: float = 0.0) -> Intrinsics:
    return Intrinsics(intr.fx * s, intr.fy * s, intr.cx + dc, intr.cy - dc, intr.width,
                      intr.height, intr.k1, intr.k2, intr.p1, intr.p2, intr.k3)  # fmt: skip


def cv2_rmse(obj, img, k, dist, rvec, tvec):
    pr, _ = cv2.projectPoints(obj, rvec, tvec, k, dist)
    return float(np.sqrt(np.mean(np.sum((pr.reshape(-1, 2) - img) ** 2, axis=1))))


def arrays(gcps):
    return (np.array([g.p_enu for g in gcps], np.float64),
            np.array([[g.u, g.v] for g in gcps], np.float64))  # fmt: skip


def test_the_peer_camera_in_the_site_frame_reprojects_its_points(case):
    obj, img = arrays(case.gcps)
    u, v, _ = case.camera.project(obj)
    err = np.hypot(u - img[:, 0], v - img[:, 1])
    # Within 2.1 px, nearly all of it the grid-scale effect (300 ppm of ~400 m at 7.5
    # cm/px): with the focal lengths scaled by k it drops below a third of a pixel.
    assert err.max() < 2.1 and len(case.gcps) == 42
    k = grid_scale_factor(case)
    cam_k = Camera(scaled(case.camera.intrinsics, k), case.camera.position_enu,
                   case.camera.R_world_cam)  # fmt: skip
    u, v, _ = cam_k.project(obj)
    assert np.hypot(u - img[:, 0], v - img[:, 1]).max() < 0.35


def test_pose_fit_matches_solvepnp_and_recovers_the_peer_pose(case, noisy):
    fit = fit_camera_to_gcps(start(case), noisy, "yaw,tilt,roll,x,y,z".split(","),
                             loss="linear", reject_outliers=False)  # fmt: skip
    obj, img = arrays(noisy)
    intr = case.camera.intrinsics
    dist = np.array(intr.coeffs)
    ok, rvec, tvec = cv2.solvePnP(obj, img, intr.K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok
    peer = cv2_rmse(obj, img, intr.K, np.array(intr.coeffs), rvec, tvec)
    assert fit.rmse_px <= peer + 1e-3, (fit.rmse_px, peer)
    assert 0.45 < fit.rmse_px < 0.8
    assert rotation_error_deg(fit.camera, case.camera) < 0.02
    d = fit.camera.position_enu - case.camera.position_enu
    assert np.hypot(d[0], d[1]) < 0.3 and abs(d[2]) < 0.5
    # Each parameter's sigma is small and consistent with its error (4 sigma + frame).
    assert fit.sigmas["tilt"] < 0.01 and fit.sigmas["z"] < 0.05


FLAGS = {
    "yaw,tilt,roll,x,y,z,fx,fy,cx,cy,k1,k2,k3,p1,p2": 0,
    "yaw,tilt,roll,x,y,z,f,cx,cy,k1,k2": cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_FIX_K3
    | cv2.CALIB_ZERO_TANGENT_DIST,
    "yaw,tilt,roll,x,y,z,fx,fy,k1": cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_K2
    | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
}  # fmt: skip


@pytest.mark.parametrize("free", list(FLAGS))
def test_intrinsics_and_pose_no_worse_than_calibrate_camera(case, noisy, free):
    first = scaled(case.camera.intrinsics, 1.01, 5.0)
    fit = fit_camera_to_gcps(start(case, first), noisy, free.split(","), loss="linear",
                             reject_outliers=False)  # fmt: skip
    obj, img = arrays(noisy)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-15)
    rms, *_ = cv2.calibrateCamera(
        [obj.astype(np.float32)], [img.astype(np.float32)], (first.width, first.height),
        first.K.copy(), np.array(first.coeffs, float).reshape(1, 5),
        flags=cv2.CALIB_USE_INTRINSIC_GUESS | FLAGS[free], criteria=crit,
    )  # fmt: skip
    assert fit.converged
    assert fit.rmse_px <= rms + 1e-3, (fit.rmse_px, rms)


def grid_scale_factor(case) -> float:
    lat, lon, _ = case.frame.to_geodetic(*case.camera.position_enu)
    return float(Proj(CRS).get_factors(lon, lat).meridional_scale)


def test_focal_lengths_apart_recover_the_peer_focal_length(case, noisy):
    i0 = case.camera.intrinsics
    cam0 = start(case, scaled(i0, 1.03), move_m=(0.0, 0.0, 0.0))
    fit = fit_camera_to_gcps(cam0, noisy, ["yaw", "tilt", "roll", "fx", "fy"], loss="linear",
                             reject_outliers=False)  # fmt: skip
    k = grid_scale_factor(case)
    assert 0.9996 < k < 0.9998
    want = i0.fx * k  # see the module notes
    for name in ("fx", "fy"):
        assert abs(fit.values[name] - want) < 4 * fit.sigmas[name] + 0.5, (name, fit.values, want)
    assert abs(fit.values["fx"] - i0.fx) < 5.0
    assert rotation_error_deg(fit.camera, case.camera) < 0.005


def corrupt(case, noisy):
    """Three 30 px blunders, three GCPs near the centre raised 1, 2, 3 m."""
    obj, img = arrays(case.gcps)
    c = case.camera.intrinsics
    r = np.hypot(img[:, 0] - c.cx, img[:, 1] - c.cy)
    lifted = [int(i) for i in np.argsort(r)[:3]]
    rng = np.random.default_rng(1)
    rest = [i for i in range(len(noisy)) if i not in lifted]
    blunders = sorted(int(i) for i in rng.choice(rest, 3, replace=False))
    out = list(noisy)
    for i in blunders:
        g = out[i]
        out[i] = Gcp(g.name, g.u + 24.0, g.v - 18.0, g.p_enu)
    for dz, i in zip((1.0, 2.0, 3.0), lifted, strict=True):
        g = out[i]
        out[i] = Gcp(g.name, g.u, g.v, g.p_enu + np.array([0.0, 0.0, dz]))
    return out, blunders, lifted


def test_blunders_and_gcps_above_the_dem_are_flagged(case, noisy):
    gcps, blunders, lifted = corrupt(case, noisy)
    fit = fit_camera_to_gcps(start(case), gcps, "yaw,tilt,roll,x,y,z".split(","))
    flagged = set(np.flatnonzero(fit.outliers).tolist())
    # Every blunder; a GCP raised 3 m off-centre also moves its pixel by several px.
    assert set(blunders) <= flagged <= set(blunders) | set(lifted)
    assert fit.rmse_px < 0.8 and fit.rmse_all_px > 5.0
    dem = check_gcps_on_dem(fit.camera, gcps, case.dem)
    assert sorted(np.flatnonzero(dem.flagged).tolist()) == sorted(lifted)
    for dz, i in zip((1.0, 2.0, 3.0), lifted, strict=True):
        assert dem.dh_m[i] == pytest.approx(dz, abs=0.3)
        assert dem.ray[i] == "passes over" and "above the DEM" in dem.reasons[i]
    # The others sit on the DEM (the import's resampling is the only difference).
    ok = ~dem.flagged
    assert np.abs(np.asarray(dem.dh_m)[ok]).max() < 0.3
    loo = leave_one_out(gcps, fit, case.dem)
    clean = np.array([s == "ok" for s in loo.status]) & ok
    h = loo.horizontal_error_m[clean]
    # 0.5 px at 7.5 cm/px: decimetres on the ground, horizontally and vertically.
    assert np.sqrt(np.mean(h**2)) < 0.15 and np.abs(loo.vertical_error_m[clean]).max() < 0.3
    # No worse than the peer's own camera geolocating the same (noisy) pixels.
    idx = np.flatnonzero(clean)
    o, d = case.camera.pixel_to_ray(
        np.array([gcps[i].u for i in idx]), np.array([gcps[i].v for i in idx])
    )
    hits = cast_rays(case.dem, o, d, 5000.0, mode="first")
    p_hit = hits.points[hits.offsets[: len(idx)]]
    q = np.array([gcps[i].p_enu for i in idx])
    peer_h = np.hypot(p_hit[:, 0] - q[:, 0], p_hit[:, 1] - q[:, 1])
    assert np.sqrt(np.mean(h**2)) <= np.sqrt(np.mean(peer_h**2))
    # Excluding the DEM-flagged GCPs too leaves the fit on the 36 clean ones.
    again = fit_camera_to_gcps(start(case), gcps, "yaw,tilt,roll,x,y,z".split(","),
                               exclude=np.asarray(dem.flagged))  # fmt: skip
    assert int((~again.excluded).sum()) == 36 and again.rmse_px < 0.8


def test_utm_conversion_of_the_peer_points_matches_pyproj(case):
    # The site-frame GCPs go back to the DEM CRS through pyproj unchanged.
    obj, _ = arrays(case.gcps)
    lat, lon, h = case.frame.to_geodetic(obj[:, 0], obj[:, 1], obj[:, 2])
    x, y = Transformer.from_crs("EPSG:4326", CRS, always_xy=True).transform(lon, lat)
    doc = json.loads((DATA / "cases.json").read_text())
    ref = next(c for c in doc["cases"] if c["id"] == "tennis_court_dem01")["peer_reference"]
    assert np.hypot(x[0] - ref["grid"][0]["xyz"][0], y[0] - ref["grid"][0]["xyz"][1]) < 1e-6
    assert h[0] == pytest.approx(ref["grid"][0]["xyz"][2], abs=1e-6)
