"""GCP calibration: synthetic GCPs projected from a known camera, with noise.

Oracle: the known true camera. GCPs are ground points where rays of the true camera meet
a DEM; their pixels get Gaussian noise (fixed seed). The fit, started from a perturbed
camera, must recover the true parameters within a few times their standard error, flag a
blunder, and the leave-one-out ground errors must match the pixel noise times the ground
metres per pixel.
"""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

from demtrack.core.camera.gcp_calibration import fit_camera_to_gcps, parse_free
from demtrack.core.camera.gcp_io import Gcp, gcps_to_local, read_gcp_csv
from demtrack.core.camera.gcp_loo import leave_one_out
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CalibrationError, InputFileError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.raycast.cast import cast_rays
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

TRUE_INTR = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720, k1=-0.05)
TRUE = Camera.from_azimuth_tilt_roll(TRUE_INTR, [0.0, 0.0, 40.0], 30.0, -8.0, 1.5)
GRID = GridSpec(-300.0, 1300.0, 2.0, 800, 800)


@pytest.fixture(scope="module")
def dem():
    e, n = GRID.centres()
    return Dem(GRID, 0.02 * e + 0.01 * n + 3.0 * np.sin(e / 150.0))


def make_gcps(dem, k=14, noise_px=0.5, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(40, 1240, 4 * k)
    v = rng.uniform(430, 700, 4 * k)
    o, d = TRUE.pixel_to_ray(u, v)
    hits = cast_rays(dem, o, d, 5000.0, mode="first")
    ok = np.flatnonzero(hits.counts > 0)[:k]
    pts = hits.points[hits.offsets[ok]]
    return [
        Gcp(f"g{i}", u[j] + rng.normal(0, noise_px), v[j] + rng.normal(0, noise_px), pts[i])
        for i, j in enumerate(ok)
    ]


START = Camera.from_azimuth_tilt_roll(
    Intrinsics(1080.0, 1080.0, 639.5, 359.5, 1280, 720), [0.0, 0.0, 40.0], 42.0, -3.0, 0.0
)
# The same wrong pose on the true lens, for fits that free the orientation only.
START_POSE = Camera.from_azimuth_tilt_roll(TRUE_INTR, [0.0, 0.0, 40.0], 42.0, -3.0, 0.0)


def test_recovers_orientation_focal_length_and_k1(dem):
    gcps = make_gcps(dem)
    fit = fit_camera_to_gcps(START, gcps, parse_free("k1,f,roll,tilt,yaw"))
    assert fit.free == ("yaw", "tilt", "roll", "f", "k1")
    az, tilt, roll = fit.camera.azimuth_tilt_roll_deg()
    truth = {"yaw": 30.0, "tilt": -8.0, "roll": 1.5, "f": 1000.0, "k1": -0.05}
    for name, value in truth.items():
        err = abs(fit.values[name] - value)
        # Within 4 standard errors, and the standard errors are small in absolute terms.
        assert err < 4 * fit.sigmas[name], (name, fit.values[name], fit.sigmas[name])
    assert fit.sigmas["yaw"] < 0.05 and fit.sigmas["f"] < 5.0
    assert (az, tilt, roll) == pytest.approx((30.0, -8.0, 1.5), abs=0.1)
    # 0.5 px per axis: |r| has RMS 0.5 * sqrt(2) = 0.71 px, less the fitted dof.
    assert 0.4 < fit.rmse_px < 0.8
    assert not fit.outliers.any() and fit.converged


def test_a_lens_with_an_r8_term_keeps_it_through_the_fit(dem):
    # GCPs seen through a lens with k4 (weitsicht's / Metashape's r^8 term); the fit frees
    # the orientation only and must neither drop k4 nor absorb it into the pose.
    lens = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720, k1=-0.05, k4=0.002)
    true = Camera.from_azimuth_tilt_roll(lens, [0.0, 0.0, 40.0], 30.0, -8.0, 1.5)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(40, 1240, 80), rng.uniform(430, 700, 80)
    o, d = true.pixel_to_ray(u, v)
    hits = cast_rays(dem, o, d, 5000.0, mode="first")
    ok = np.flatnonzero(hits.counts > 0)[:14]
    pts = hits.points[hits.offsets[ok]]
    gcps = [Gcp(f"g{i}", u[j], v[j], pts[i]) for i, j in enumerate(ok)]
    start = Camera.from_azimuth_tilt_roll(lens, [0.0, 0.0, 40.0], 33.0, -6.0, 0.0)
    fit = fit_camera_to_gcps(start, gcps, parse_free("yaw,tilt,roll"))
    assert fit.camera.intrinsics.k4 == 0.002
    assert fit.rmse_px < 1e-3  # noise-free: exact with the lens as it is
    assert fit.camera.azimuth_tilt_roll_deg() == pytest.approx((30.0, -8.0, 1.5), abs=1e-5)


def test_injected_blunder_is_flagged_excluded_and_does_not_bias(dem):
    gcps = make_gcps(dem)
    clean = fit_camera_to_gcps(START_POSE, gcps, ("yaw", "tilt", "roll"))
    bad = list(gcps)
    bad[5] = Gcp("blunder", gcps[5].u + 30.0, gcps[5].v - 12.0, gcps[5].p_enu)
    fit = fit_camera_to_gcps(START_POSE, bad, ("yaw", "tilt", "roll"))
    assert list(np.flatnonzero(fit.outliers)) == [5] and fit.excluded[5]
    assert fit.residual_norms_px[5] > 25.0
    assert any("'blunder'" in w and "excluded" in w for w in fit.warnings)
    for name in ("yaw", "tilt", "roll"):
        assert fit.values[name] == pytest.approx(clean.values[name], abs=0.01)
    kept = fit_camera_to_gcps(START_POSE, bad, ("yaw", "tilt", "roll"), reject_outliers=False)
    assert kept.outliers[5] and not kept.excluded[5]
    # Plain least squares with the blunder kept is pulled off (robust loss is not).
    plain = fit_camera_to_gcps(
        START_POSE, bad, ("yaw", "tilt", "roll"), loss="linear", reject_outliers=False
    )
    assert abs(plain.values["yaw"] - 30.0) > 5 * abs(fit.values["yaw"] - 30.0)


def test_leave_one_out_ground_errors_match_the_pixel_noise(dem):
    gcps = make_gcps(dem, k=12)
    gcps[3] = Gcp("blunder", gcps[3].u + 25.0, gcps[3].v, gcps[3].p_enu)
    fit = fit_camera_to_gcps(START_POSE, gcps, ("yaw", "tilt", "roll", "f"))
    loo = leave_one_out(gcps, fit, dem)
    ok = np.array([s == "ok" for s in loo.status])
    assert loo.status[3] == "outlier" and ok.sum() == 11
    # Each inlier's ground error is its LOO pixel error times metres per pixel, within
    # a factor for the direction of the error on the slope.
    e = loo.ground_error_m[ok]
    bound = 3.0 * loo.m_per_px[ok] * np.maximum(loo.reprojection_px[ok], 0.5)
    assert np.all(e < bound), (e, bound)
    assert np.median(e) < 1.0
    # The blunder, 25 px off, geolocates far from its survey point.
    assert loo.ground_error_m[3] > 10 * np.median(e)
    assert np.all(loo.grazing_deg[ok] > 5.0) and not loo.grazing.any()


def test_grazing_rays_are_reported(dem):
    gcps = make_gcps(dem, k=10)
    # A far GCP near the horizon: the ray meets the ground 1 km away at ~1.7 deg.
    o, d = TRUE.pixel_to_ray(640.0, 240.0)
    hit = cast_rays(dem, o, d, 20000.0, mode="first")
    gcps.append(Gcp("far", 640.0, 240.0, hit.points[0]))
    fit = fit_camera_to_gcps(START_POSE, gcps, ("yaw", "tilt", "roll"))
    loo = leave_one_out(gcps, fit, dem)
    assert loo.grazing[-1] and loo.grazing_deg[-1] < 5.0
    assert loo.m_per_px[-1] > 5 * np.median(loo.m_per_px[:-1])


def test_gcps_behind_the_camera_are_refused_in_one_line(dem):
    gcps = make_gcps(dem, k=6)
    behind = Gcp("behind", 600.0, 500.0, np.array([0.0, -200.0, 0.0]))
    with pytest.raises(CalibrationError, match="'behind' is behind") as err:
        fit_camera_to_gcps(START_POSE, [*gcps, behind])
    assert "\n" not in str(err.value)


def test_too_few_gcps_and_bad_parameter_names(dem):
    gcps = make_gcps(dem, k=2)
    with pytest.raises(CalibrationError, match="give at least 3"):
        fit_camera_to_gcps(START_POSE, gcps, ("yaw", "tilt", "roll", "f", "k1"))
    with pytest.raises(CalibrationError, match="unknown parameter"):
        parse_free("yaw,zoom")


def test_gcp_csv_in_utm_with_header_crs(tmp_path):
    frame = LocalFrame(40.3573, -79.6208, 300.0)
    pts = np.array([[100.0, 200.0, 12.0], [-50.0, 400.0, 30.0], [300.0, 800.0, 55.0]])
    lat, lon, h = frame.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2])
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:32617", always_xy=True).transform(lon, lat)
    lines = ["# crs: EPSG:32617", "# vertical: orthometric", "name,u,v,x,y,z"]
    lines += [
        f"p{i},{10 * i},{20 * i},{float(x[i])!r},{float(y[i])!r},{float(h[i]) + 33.5!r}"
        for i in range(3)
    ]
    (tmp_path / "g.csv").write_text("\n".join(lines) + "\n")
    gf = read_gcp_csv(tmp_path / "g.csv")
    assert gf.crs == "EPSG:32617" and gf.vertical == "orthometric"
    gcps = gcps_to_local(gf, frame, geoid_undulation_m=-33.5)
    np.testing.assert_allclose([g.p_enu for g in gcps], pts, atol=1e-6)
    assert [g.name for g in gcps] == ["p0", "p1", "p2"] and gcps[2].v == 40.0
    # Without a vertical datum the file is refused (a height is never guessed).
    (tmp_path / "h.csv").write_text("\n".join([lines[0], *lines[2:]]) + "\n")
    with pytest.raises(CalibrationError, match="vertical datum is not stated"):
        gcps_to_local(read_gcp_csv(tmp_path / "h.csv"), frame)
    (tmp_path / "n.csv").write_text("\n".join(lines[2:]) + "\n")
    with pytest.raises(CalibrationError, match="CRS is not stated"):
        gcps_to_local(read_gcp_csv(tmp_path / "n.csv"), frame)
    (tmp_path / "b.csv").write_text("u,v,x,y\n1,2,3,4\n")
    with pytest.raises(InputFileError, match="missing z"):
        read_gcp_csv(tmp_path / "b.csv")
