"""Free parameters, bounds, priors and the covariance of a GCP fit.

Oracles: a known camera whose lens has fx != fy, a shifted principal point and all five
distortion terms (the fit must recover each within a few of its own sigmas); Monte Carlo
over 60 noise draws (fixed seeds) for the covariance: the spread of the fitted values must
match the reported sigmas; a prior with a tiny sigma pins its parameter; a bound holds.
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.gcp_calibration import fit_camera_to_gcps
from demtrack.core.camera.gcp_io import Gcp
from demtrack.core.camera.gcp_model import parse_bounds, parse_free, parse_priors
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CalibrationError

TRUE_I = Intrinsics(1010.0, 990.0, 652.0, 351.0, 1280, 720, -0.08, 0.02, 0.001, -0.0015, 0.004)
TRUE = Camera.from_azimuth_tilt_roll(TRUE_I, [5.0, -3.0, 30.0], 40.0, -12.0, 1.0)


def world_points(n=80, seed=0):
    """Points seen by TRUE over its whole image, 60-400 m away (a 3-D scene)."""
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 1279, n), rng.uniform(0, 719, n)
    o, d = TRUE.pixel_to_ray(u, v)
    return o + d * rng.uniform(60, 400, n)[:, None]


def gcps_for(cam, pts, noise_px, seed):
    u, v, _ = cam.project(pts)
    rng = np.random.default_rng(seed)
    return [
        Gcp(f"g{k}", u[k] + rng.normal(0, noise_px), v[k] + rng.normal(0, noise_px), pts[k])
        for k in range(len(pts))
    ]


def start_camera():
    i = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    return Camera.from_azimuth_tilt_roll(i, [5.0, -3.0, 30.0], 38.5, -11.0, 0.0)


ALL_LENS = "yaw,tilt,roll,fx,fy,cx,cy,k1,k2,k3,p1,p2"


def test_every_lens_term_is_recovered_apart():
    fit = fit_camera_to_gcps(
        start_camera(), gcps_for(TRUE, world_points(), 0.3, 1), ALL_LENS.split(","), loss="linear"
    )
    truth = dict(
        yaw=40.0, tilt=-12.0, roll=1.0, fx=1010.0, fy=990.0, cx=652.0, cy=351.0,
        k1=-0.08, k2=0.02, k3=0.004, p1=0.001, p2=-0.0015,
    )  # fmt: skip
    for name, value in truth.items():
        assert abs(fit.values[name] - value) < 4.5 * fit.sigmas[name], (name, fit.values[name])
    assert abs(fit.values["fx"] - fit.values["fy"]) > 10.0  # apart, as the lens is
    assert fit.rmse_px < 0.5 and fit.converged
    assert fit.covariance.shape == (12, 12)


def test_sigmas_match_the_spread_over_noise_draws():
    pts = world_points(30, seed=2)
    free = ["yaw", "tilt", "roll", "fx", "fy", "cx", "cy"]
    lens = Intrinsics(1010.0, 990.0, 652.0, 351.0, 1280, 720)
    cam = Camera(lens, TRUE.position_enu, TRUE.R_world_cam)
    start = Camera(Intrinsics(1000.0, 1000.0, 640.0, 360.0, 1280, 720), cam.position_enu,
                   cam.R_world_cam)  # fmt: skip
    values, sigmas = [], []
    for seed in range(60):
        fit = fit_camera_to_gcps(start, gcps_for(cam, pts, 1.0, 100 + seed), free, loss="linear")
        values.append([fit.values[n] for n in free])
        sigmas.append([fit.sigmas[n] for n in free])
    spread = np.std(np.array(values), axis=0, ddof=1)
    predicted = np.median(np.array(sigmas), axis=0)
    # 60 draws: the sample std is within ~ +-25 % of the true one (95 %).
    np.testing.assert_allclose(spread / predicted, 1.0, atol=0.3)


def test_priors_and_bounds():
    gcps = gcps_for(TRUE, world_points(12, seed=3), 0.5, 4)
    cam0 = Camera(TRUE_I, TRUE.position_enu + [3.0, -2.0, 1.0], TRUE.R_world_cam)
    free = ["yaw", "tilt", "roll", "x", "y", "z"]
    pinned = fit_camera_to_gcps(
        cam0, gcps, free, priors={"x": (5.0, 1e-4), "y": (-3.0, 1e-4), "z": (30.0, 1e-4)}
    )
    assert pinned.camera.position_enu == pytest.approx([5.0, -3.0, 30.0], abs=1e-3)
    assert pinned.sigmas["x"] < 2e-4
    loose = fit_camera_to_gcps(cam0, gcps, free)
    assert loose.sigmas["x"] > 10 * pinned.sigmas["x"]
    held = fit_camera_to_gcps(cam0, gcps, free, bounds={"z": (30.5, 32.0)})
    assert held.values["z"] == pytest.approx(30.5, abs=1e-6)
    assert any("z ended on its bound" in w for w in held.warnings)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: parse_free("f,fx"), "free either f or fx,fy"),
        (lambda: parse_free("yaw,fz"), "unknown parameter"),
        (lambda: parse_bounds(["fx=1100,900"]), "lower bound must be below"),
        (lambda: parse_bounds(["fx=1100"]), "is malformed: write NAME=LO,HI"),
        (lambda: parse_priors(["fx=1000,0"]), "sigma must be positive"),
        (lambda: parse_priors(["zoom=1,1"]), "unknown parameter 'zoom'"),
        (
            lambda: fit_camera_to_gcps(
                start_camera(), gcps_for(TRUE, world_points(10), 0.3, 0), ["yaw", "fx"],
                bounds={"fx": (1100.0, 1200.0)},
            ),
            "excludes its starting value 1000",
        ),
        (
            lambda: fit_camera_to_gcps(
                start_camera(), gcps_for(TRUE, world_points(10), 0.3, 0), ["yaw"],
                priors={"fx": (1000.0, 5.0)},
            ),
            "'fx' is not a free parameter",
        ),
    ],
)  # fmt: skip
def test_bad_model_input_is_one_line(call, message):
    with pytest.raises(CalibrationError, match=message) as err:
        call()
    assert "\n" not in str(err.value)
