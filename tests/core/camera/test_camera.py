from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.camera.pinhole import (
    Camera,
    Intrinsics,
    distort_normalized,
    distortion_jacobian,
    radial_fold_radius,
    rotation_from_azimuth_tilt_roll,
    undistort_normalized,
    undistort_normalized_nb,
)
from demtrack.core.errors import CameraError

W, H = 1920, 1080
PLAIN = Intrinsics(1000.0, 1000.0, (W - 1) / 2, (H - 1) / 2, W, H)
# Strong barrel (wide-angle security lens): OpenCV's fixed-point loop fails at the corners.
BARREL = Intrinsics(1000.0, 1005.0, 955.25, 541.75, W, H, k1=-0.4, k2=0.1)
# Barrel with tangential terms and a k3 that makes the model fold far outside the image.
WILD = Intrinsics(
    1000.0, 1000.0, 959.5, 539.5, W, H, k1=-0.5, k2=0.2, p1=0.001, p2=-0.002, k3=-0.01
)
PINCUSHION = Intrinsics(1400.0, 1400.0, 970.0, 530.0, W, H, k1=0.15, k2=0.05)
# A real aerial camera with an r^8 term (weitsicht's ariel right camera, pre-calibrated).
ARIEL = Intrinsics(
    9524.786, 9524.788, 5811.896, 4422.312, 11664, 8750,
    k1=0.01598, k2=-0.07004, p1=1.016e-05, p2=1.284e-05, k3=0.0194, k4=0.006022,
)  # fmt: skip
LENSES = [PLAIN, BARREL, WILD, PINCUSHION, ARIEL]


def image_grid(intr: Intrinsics, n: int = 41) -> tuple[np.ndarray, np.ndarray]:
    """Pixels over the whole image, its four outer corners and edges included."""
    uu, vv = np.meshgrid(
        np.linspace(-0.5, intr.width - 0.5, n), np.linspace(-0.5, intr.height - 0.5, n)
    )
    return uu.ravel(), vv.ravel()


def opencv_formula(x, y, k1, k2, p1, p2, k3, k4=0.0):
    """The distortion as OpenCV documents it (plus ``k4 r^8``), written out independently."""
    r2 = x**2 + y**2
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3 + k4 * r2**4
    return (
        x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x**2),
        y * radial + p1 * (r2 + 2 * y**2) + 2 * p2 * x * y,
    )


def opencv_fixed_point(xd, yd, k1, k2, p1, p2, k3, k4=0.0, iters=20):
    """cv::undistortPoints' iteration: x <- (xd - tangential(x)) / radial(x)."""
    x, y = xd.copy(), yd.copy()
    for _ in range(iters):
        r2 = x * x + y * y
        g = 1 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
        x, y = (
            (xd - (2 * p1 * x * y + p2 * (r2 + 2 * x * x))) / g,
            (yd - (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)) / g,
        )
    return x, y


# --- Intrinsics validation ---------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(fx=0.0),
        dict(fy=-5.0),
        dict(fx=float("nan")),
        dict(cx=float("inf")),
        dict(width=0),
        dict(height=-3),
        dict(width=10.5),
        dict(k1=float("nan")),
        dict(fx="a"),
    ],
)
def test_intrinsics_rejects_bad_values(kwargs):
    args = dict(fx=800.0, fy=800.0, cx=320.0, cy=240.0, width=640, height=480) | kwargs
    with pytest.raises(CameraError):
        Intrinsics(**args)
    with pytest.raises(ValueError):  # CameraError is also a ValueError
        Intrinsics(**args)


def test_intrinsics_normalises_types():
    intr = Intrinsics(800, 800, 320, 240, 640.0, 480.0)
    assert isinstance(intr.width, int) and isinstance(intr.fx, float)
    assert not intr.has_distortion and BARREL.has_distortion
    np.testing.assert_array_equal(intr.K, [[800, 0, 320], [0, 800, 240], [0, 0, 1]])


# --- Pixel convention ----------------------------------------------------------------------


def test_in_image_edges_follow_pixel_centre_convention():
    intr = Intrinsics(500.0, 500.0, 1.5, 1.0, 4, 3)
    u = np.array([-0.5, 3.5, -0.5 - 1e-9, 3.5 + 1e-9, 0.0, np.nan])
    v = np.array([-0.5, 2.5, 0.0, 0.0, 2.5 + 1e-9, 0.0])
    np.testing.assert_array_equal(intr.in_image(u, v), [True, True, False, False, False, False])


def test_half_pixel_convention_field_of_view():
    # With cx = (W-1)/2 the image's outer edges are at u = -0.5 and W - 0.5, so the
    # horizontal field of view is exactly 2 atan(W / (2 fx)).
    cam = Camera.from_azimuth_tilt_roll(PLAIN, [0, 0, 0], 30.0, -10.0)
    _, d = cam.pixel_to_ray([-0.5, W - 0.5], [PLAIN.cy, PLAIN.cy])
    angle = math.acos(float(d[0] @ d[1]))
    assert angle == pytest.approx(2 * math.atan(W / (2 * PLAIN.fx)), abs=1e-12)
    # Pixel (0, 0) and (W-1, H-1) are mirror images through the optical axis.
    _, d = cam.pixel_to_ray([0.0, W - 1.0], [0.0, H - 1.0])
    axis = cam.R_world_cam[:, 2]
    np.testing.assert_allclose(d[0] + d[1], 2 * (d[0] @ axis) * axis, atol=1e-15)


@pytest.mark.parametrize("intr", LENSES)
def test_optical_axis_projects_to_principal_point(intr):
    cam = Camera.from_azimuth_tilt_roll(intr, [10.0, -4.0, 25.0], 123.0, -17.0, 3.0)
    u, v, front = cam.project(cam.position_enu + 50.0 * cam.R_world_cam[:, 2])
    assert front[0]
    assert u[0] == pytest.approx(intr.cx, abs=1e-9)
    assert v[0] == pytest.approx(intr.cy, abs=1e-9)
    _, d = cam.pixel_to_ray(intr.cx, intr.cy)
    np.testing.assert_allclose(d[0], cam.R_world_cam[:, 2], atol=1e-15)


# --- Distortion ----------------------------------------------------------------------------


def test_distortion_matches_opencv_formula_and_jacobian():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1.2, 1.2, (2, 500))
    for intr in LENSES:
        xd, yd = distort_normalized(x, y, *intr.lens_coeffs)
        ex, ey = opencv_formula(x, y, *intr.lens_coeffs)
        np.testing.assert_allclose(xd, ex, rtol=0, atol=1e-14)
        np.testing.assert_allclose(yd, ey, rtol=0, atol=1e-14)
        h = 1e-6
        jac = distortion_jacobian(x, y, *intr.lens_coeffs)
        fd = [
            (
                np.subtract(
                    *[distort_normalized(x + s * h, y, *intr.lens_coeffs)[i] for s in (1, -1)]
                )
            )
            / (2 * h)
            for i in (0, 1)
        ]
        fdy = [
            (
                np.subtract(
                    *[distort_normalized(x, y + s * h, *intr.lens_coeffs)[i] for s in (1, -1)]
                )
            )
            / (2 * h)
            for i in (0, 1)
        ]
        np.testing.assert_allclose(jac[0], fd[0], atol=1e-7)
        np.testing.assert_allclose(jac[1], fdy[0], atol=1e-7)
        np.testing.assert_allclose(jac[2], fd[1], atol=1e-7)
        np.testing.assert_allclose(jac[3], fdy[1], atol=1e-7)


def test_radial_fold_radius_analytic():
    assert radial_fold_radius(0.0, 0.0, 0.0) == math.inf
    assert radial_fold_radius(0.2, 0.1, 0.0) == math.inf
    # Denormal and tiny coefficients neither crash the root finder nor invent folds.
    assert radial_fold_radius(0.0, 2.2250738585e-313, 0.0) == math.inf
    assert radial_fold_radius(1e-300, -1e-300, 1e-300) == math.inf
    # 1 + 3 k1 r^2 = 0
    assert radial_fold_radius(-0.1, 0.0, 0.0) == pytest.approx(math.sqrt(1 / 0.3), rel=1e-12)
    # 1 + 5 k2 r^4 = 0
    assert radial_fold_radius(0.0, -0.05, 0.0) == pytest.approx((1 / 0.25) ** 0.25, rel=1e-12)
    # 1 + 9 k4 r^8 = 0
    assert radial_fold_radius(0.0, 0.0, 0.0, -0.01) == pytest.approx((1 / 0.09) ** 0.125, rel=1e-12)
    assert radial_fold_radius(0.0, 0.0, 0.0, 0.01) == math.inf


@pytest.mark.parametrize("intr", LENSES)
def test_undistort_is_exact_inverse_over_image(intr):
    u, v = image_grid(intr)
    xn, yn = intr.undistort(u, v)
    assert np.isfinite(xn).all() and np.isfinite(yn).all()
    u2, v2 = intr.distort(xn, yn)
    assert np.abs(u2 - u).max() < 1e-9
    assert np.abs(v2 - v).max() < 1e-9
    # The other way round, on the ideal coordinates of those pixels.
    xn2, yn2 = intr.undistort(u2, v2)
    np.testing.assert_allclose(xn2, xn, rtol=0, atol=1e-12)
    np.testing.assert_allclose(yn2, yn, rtol=0, atol=1e-12)


def test_newton_succeeds_where_opencv_fixed_point_fails():
    u, v = BARREL.corners_px()
    xd, yd = (u - BARREL.cx) / BARREL.fx, (v - BARREL.cy) / BARREL.fy
    xf, yf = opencv_fixed_point(xd, yd, *BARREL.coeffs)
    uf, vf = BARREL.distort(xf, yf)
    assert np.nanmax(np.hypot(uf - u, vf - v)) > 1.0  # the plain loop is pixels off
    xn, yn = BARREL.undistort(u, v)
    un, vn = BARREL.distort(xn, yn)
    assert np.hypot(un - u, vn - v).max() < 1e-9


def test_compiled_undistort_matches_numpy_twin():
    rng = np.random.default_rng(0)
    for intr in LENSES + [Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H, k1=-0.1)]:
        # Well beyond the image too, where the folded model has no preimage.
        u = rng.uniform(-3 * W, 4 * W, 3000)
        v = rng.uniform(-3 * H, 4 * H, 3000)
        u[:3], v[:3] = np.nan, 0.0
        xd, yd = (u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy
        a = undistort_normalized(xd, yd, *intr.lens_coeffs, r_max=intr.fold_radius)
        b = undistort_normalized_nb(xd, yd, *intr.lens_coeffs, r_max=intr.fold_radius)
        for p, q in zip(a, b, strict=True):
            np.testing.assert_array_equal(np.isnan(p), np.isnan(q))
            np.testing.assert_allclose(p, q, rtol=0, atol=1e-12)
        assert np.isnan(a[0][:3]).all()


def test_lens_folding_inside_image_is_rejected():
    # r (1 - 0.5 r^2) peaks at r = sqrt(2/3), distorted radius 0.544 < corner radius 1.10.
    with pytest.raises(CameraError, match="not invertible"):
        Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H, k1=-0.5)
    # Same lens on a small enough sensor is fine.
    Intrinsics(1000.0, 1000.0, 199.5, 199.5, 400, 400, k1=-0.5)


def test_r8_term_folds_and_is_rejected():
    # k4 alone: 1 + 9 k4 r^8 = 0 at r = 0.829, distorted radius 0.737 < corner radius 1.10.
    with pytest.raises(CameraError, match="not invertible"):
        Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H, k4=-0.5)
    # Dropping k4 from the same lens is a different, valid camera: k4 is really used.
    Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H)


def test_r8_term_moves_the_image_corners_as_its_formula_says():
    # At the corners of the ariel camera r^2 = 0.59-0.61: k4 r^8 moves them radially by
    # fx * r * k4 * r^8 = 5.4-6.0 px against the same lens without it.
    u, v = ARIEL.corners_px()
    no_k4 = Intrinsics(**{**ARIEL.to_dict(), "k4": 0.0})
    xn, yn = ARIEL.undistort(u, v)
    u0, v0 = no_k4.distort(xn, yn)
    r2 = xn**2 + yn**2
    expect = ARIEL.fx * np.sqrt(r2) * ARIEL.k4 * r2**4
    np.testing.assert_allclose(np.hypot(u0 - u, v0 - v), expect, rtol=1e-5)
    assert np.hypot(u0 - u, v0 - v).min() > 5.0


def test_tangential_fold_is_rejected():
    with pytest.raises(CameraError, match="not invertible"):
        Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H, p1=0.6)


def test_points_beyond_the_fold_do_not_project_into_the_image():
    # k1 = -0.1 folds at r = 1.826 (outside the image). A ray at r = 3 would distort to
    # r_d = 3 (1 - 0.9) = 0.3, i.e. 300 px from the centre, inside the image: refuse it.
    intr = Intrinsics(1000.0, 1000.0, 959.5, 539.5, W, H, k1=-0.1)
    u, v = intr.distort([3.0, 1.0], [0.0, 0.0])
    assert np.isnan(u[0]) and np.isnan(v[0])
    assert u[1] == pytest.approx(959.5 + 1000.0 * 0.9)
    cam = Camera(intr, [0, 0, 0], np.eye(3))
    u, v, front = cam.project([[3.0, 0.0, 1.0]])
    assert front[0] and np.isnan(u[0])
    # Beyond the largest distorted radius there is no preimage at all.
    xn, _ = intr.undistort(959.5 + 1000.0 * 1.3, 539.5)
    assert np.isnan(xn)


# --- Pose ----------------------------------------------------------------------------------


def test_azimuth_tilt_roll_axes():
    r = rotation_from_azimuth_tilt_roll(0.0, 0.0)
    np.testing.assert_allclose(r, [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-15)
    r = rotation_from_azimuth_tilt_roll(90.0, 0.0)  # looking east: right is south
    np.testing.assert_allclose(r[:, 2], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(r[:, 0], [0, -1, 0], atol=1e-15)
    r = rotation_from_azimuth_tilt_roll(0.0, -30.0)  # looking north, down 30 degrees
    np.testing.assert_allclose(r[:, 2], [0, math.cos(math.radians(30)), -0.5], atol=1e-15)
    r = rotation_from_azimuth_tilt_roll(200.0, -90.0)  # straight down
    np.testing.assert_allclose(r[:, 2], [0, 0, -1], atol=1e-15)


def test_tilt_up_moves_scene_down_and_positive_roll_raises_right_horizon():
    intr = PLAIN
    level = Camera.from_azimuth_tilt_roll(intr, [0, 0, 0], 45.0, 0.0)
    up = Camera.from_azimuth_tilt_roll(intr, [0, 0, 0], 45.0, 5.0)
    rolled = Camera.from_azimuth_tilt_roll(intr, [0, 0, 0], 45.0, 0.0, 10.0)
    horizon_right = np.array([[math.sin(math.radians(60)), math.cos(math.radians(60)), 0.0]])
    u, v, _ = level.project(horizon_right)
    assert u[0] > intr.cx and v[0] == pytest.approx(intr.cy)
    assert up.project(horizon_right)[1][0] > intr.cy  # camera tilted up: horizon lower
    assert rolled.project(horizon_right)[1][0] < intr.cy  # right wing down


@settings(max_examples=60, deadline=None)
@given(az=st.floats(-720, 720), tilt=st.floats(-89.9, 89.9), roll=st.floats(-179.9, 179.9))
def test_angles_round_trip(az, tilt, roll):
    cam = Camera.from_azimuth_tilt_roll(PLAIN, [0, 0, 0], az, tilt, roll)
    a, t, r = cam.azimuth_tilt_roll_deg()
    assert math.cos(math.radians(a - az)) == pytest.approx(1.0, abs=1e-12)
    assert t == pytest.approx(tilt, abs=1e-7)
    assert math.cos(math.radians(r - roll)) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(
        rotation_from_azimuth_tilt_roll(a, t, r), cam.R_world_cam, atol=1e-12
    )


def test_camera_validation():
    with pytest.raises(CameraError):
        Camera(PLAIN, [0, 0], np.eye(3))
    with pytest.raises(CameraError):
        Camera(PLAIN, [0, 0, np.nan], np.eye(3))
    with pytest.raises(CameraError, match="rotation"):
        Camera(PLAIN, [0, 0, 0], np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(CameraError, match="rotation"):
        Camera(PLAIN, [0, 0, 0], 2 * np.eye(3))
    with pytest.raises(CameraError, match="tilt"):
        Camera.from_azimuth_tilt_roll(PLAIN, [0, 0, 0], 0.0, 91.0)
    cam = Camera(PLAIN, [1, 2, 3], np.eye(3))
    with pytest.raises(ValueError):
        cam.position_enu[0] = 5.0  # frozen values hold read-only arrays


# --- pixel_to_ray / project ----------------------------------------------------------------


@pytest.mark.parametrize("intr", LENSES)
def test_project_inverts_pixel_to_ray(intr):
    rng = np.random.default_rng(0)
    cam = Camera.from_azimuth_tilt_roll(intr, [100.0, -50.0, 30.0], 250.0, -20.0, 2.0)
    u, v = image_grid(intr, 21)
    o, d = cam.pixel_to_ray(u, v, check=True)
    assert o.shape == d.shape == (u.size, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-15)
    t = rng.uniform(1.0, 5000.0, u.size)
    u2, v2, front = cam.project(o + t[:, None] * d)
    assert front.all()
    assert np.abs(u2 - u).max() < 1e-6 and np.abs(v2 - v).max() < 1e-6


@pytest.mark.parametrize("intr", LENSES)
def test_pixel_to_ray_inverts_project(intr):
    rng = np.random.default_rng(1)
    cam = Camera.from_azimuth_tilt_roll(intr, [0.0, 0.0, 10.0], 10.0, -5.0)
    # Points whose pixels fall on the image: pick pixels, push them out, perturb nothing.
    pts = cam.position_enu + rng.uniform(-400, 400, (800, 3)) + 600 * cam.R_world_cam[:, 2]
    u, v, front = cam.project(pts)
    keep = front & cam.in_image(u, v)
    assert keep.sum() > 200
    o, d = cam.pixel_to_ray(u[keep], v[keep])
    to_pt = pts[keep] - o
    to_pt /= np.linalg.norm(to_pt, axis=1, keepdims=True)
    assert np.linalg.norm(np.cross(d, to_pt), axis=1).max() < 1e-12
    assert (np.einsum("ij,ij->i", d, to_pt) > 0).all()


def test_project_behind_and_shapes():
    cam = Camera.from_azimuth_tilt_roll(BARREL, [0, 0, 0], 0.0, 0.0)
    u, v, front = cam.project([[0, 10, 0], [0, -10, 0], [0, 0, 0], [np.nan, 1, 0]])
    np.testing.assert_array_equal(front, [True, False, False, False])
    assert np.isfinite(u[0]) and np.isnan(u[1:]).all() and np.isnan(v[1:]).all()
    u, v, front = cam.project([0.0, 10.0, 0.0])
    assert u.shape == v.shape == front.shape == (1,)
    with pytest.raises(CameraError, match="shape"):
        cam.project(np.zeros((4, 2)))
    o, d = cam.pixel_to_ray(5.0, np.array([[1.0, 2.0], [3.0, 4.0]]))
    assert o.shape == d.shape == (4, 3)


def test_pixel_to_ray_check_rejects_off_image_pixels():
    cam = Camera.from_azimuth_tilt_roll(PINCUSHION, [0, 0, 0], 0.0, 0.0)
    with pytest.raises(CameraError, match=r"outside the 1920x1080 image"):
        cam.pixel_to_ray([10.0, W + 3.0], [10.0, 10.0], check=True)
    with pytest.raises(CameraError):
        cam.pixel_to_ray(np.nan, 10.0, check=True)
    # The kernel is permissive: an off-image pixel still has a ray, NaN has none.
    _, d = cam.pixel_to_ray([W + 3.0, np.nan], [10.0, 10.0])
    assert np.isfinite(d[0]).all() and np.isnan(d[1]).all()


@settings(max_examples=40, deadline=None)
@given(
    fx=st.floats(200, 5000),
    aspect=st.floats(0.9, 1.1),
    k1=st.floats(-0.3, 0.3),
    k2=st.floats(-0.05, 0.05),
    p=st.tuples(st.floats(-0.003, 0.003), st.floats(-0.003, 0.003)),
    frac=st.tuples(st.floats(0, 1), st.floats(0, 1)),
    az=st.floats(0, 360),
    tilt=st.floats(-80, 80),
    t=st.floats(0.5, 1e4),
)
def test_round_trip_property(fx, aspect, k1, k2, p, frac, az, tilt, t):
    try:
        intr = Intrinsics(fx, fx * aspect, 639.5, 359.5, 1280, 720, k1, k2, p[0], p[1])
    except CameraError:
        return  # a lens that folds inside the image is correctly refused
    cam = Camera.from_azimuth_tilt_roll(intr, [5.0, 6.0, 7.0], az, tilt)
    u0, v0 = -0.5 + 1280 * frac[0], -0.5 + 720 * frac[1]
    o, d = cam.pixel_to_ray(u0, v0, check=True)
    u, v, front = cam.project(o + t * d)
    assert front[0]
    assert abs(u[0] - u0) < 1e-6 and abs(v[0] - v0) < 1e-6


# --- Serialisation -------------------------------------------------------------------------


def test_to_dict_round_trips_through_json():
    cam = Camera.from_azimuth_tilt_roll(WILD, [1.25, -3.5, 12.0], 271.3, -12.7, 0.4)
    doc = json.loads(json.dumps(cam.to_dict()))
    assert doc["format"] == "demtrack.camera" and doc["version"] == 1
    assert Camera.from_dict(doc) == cam
    assert Intrinsics.from_dict(WILD.to_dict()) == WILD
    # k4 is written only when it is not 0, so five-coefficient documents stay as they were.
    assert "k4" not in WILD.to_dict()
    assert ARIEL.to_dict()["k4"] == 0.006022
    assert Intrinsics.from_dict(json.loads(json.dumps(ARIEL.to_dict()))) == ARIEL
    # coeffs stays OpenCV's five (cv2's distCoeffs); the lens takes all six.
    assert len(ARIEL.coeffs) == 5 and ARIEL.lens_coeffs[5] == 0.006022


def test_from_dict_accepts_orientation_angles():
    doc = Camera.from_azimuth_tilt_roll(PLAIN, [0, 0, 5], 30.0, -10.0).to_dict()
    del doc["R_world_cam"]
    doc["orientation"] = {"az_deg": 30.0, "tilt_deg": -10.0}
    cam = Camera.from_dict(doc)
    np.testing.assert_allclose(cam.azimuth_tilt_roll_deg(), (30.0, -10.0, 0.0), atol=1e-12)
    del doc["intrinsics"]["k1"]  # distortion keys default to zero
    Camera.from_dict(doc)


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d.update(format="other"),
        lambda d: d.update(version=2),
        lambda d: d.update(extra=1),
        lambda d: d.pop("position_enu"),
        lambda d: d.update(orientation={"az_deg": 0.0, "tilt_deg": 0.0}),  # both forms
        lambda d: d["intrinsics"].update(k_1=0.1),
        lambda d: d["intrinsics"].pop("fx"),
    ],
)
def test_from_dict_rejects_malformed(change):
    doc = Camera(PLAIN, [0, 0, 0], np.eye(3)).to_dict()
    change(doc)
    with pytest.raises(CameraError):
        Camera.from_dict(doc)


def test_in_view_is_in_front_and_on_the_image():
    from demtrack.core.camera.pinhole import Camera, Intrinsics

    intr = Intrinsics(100.0, 100.0, 49.5, 39.5, 100, 80)
    cam = Camera.from_azimuth_tilt_roll(intr, [0.0, 0.0, 0.0], 0.0, 0.0, 0.0)
    pts = np.array([[0.0, 10.0, 0.0], [0.0, -10.0, 0.0], [20.0, 10.0, 0.0], [4.9, 10.0, 3.9]])
    # Ahead and centred; behind; far off to the side; just inside the corner.
    assert cam.in_view(pts).tolist() == [True, False, False, True]
