"""Posed views: per-pixel rotations give the fixed camera's rays when they are all one."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.camera.zoom_lens import intrinsics_for_hfov
from demtrack.core.errors import CameraError
from demtrack.core.geolocation.geolocate import _pixel_perturbations
from demtrack.core.geolocation.posed_rays import PosedView, posed_view_rays

INTR = Intrinsics(900.0, 905.0, 321.0, 238.0, 640, 480, k1=-0.12, k2=0.03, p1=2e-4, p2=-1e-4)


def test_one_rotation_for_all_pixels_is_the_fixed_camera():
    rng = np.random.default_rng(0)
    cam = Camera.from_azimuth_tilt_roll(INTR, [10.0, -5.0, 30.0], 47.0, -12.0, 2.5)
    u, v = rng.uniform(-0.5, 639.5, 50), rng.uniform(-0.5, 479.5, 50)
    view = PosedView(
        INTR, u, v, np.repeat(cam.R_world_cam[None], 50, 0), np.tile(cam.position_enu, (50, 1))
    )
    o, d, axes, sig = posed_view_rays(view, 1.5)
    o_ref, d_ref = cam.pixel_to_ray(u, v)
    axes_ref, sig_ref = _pixel_perturbations(cam, u, v, 1.5)
    np.testing.assert_allclose(o, o_ref, atol=0)
    np.testing.assert_allclose(d, d_ref, atol=1e-15)
    np.testing.assert_allclose(axes, axes_ref, atol=1e-14)
    np.testing.assert_allclose(sig, sig_ref, rtol=1e-13)


def test_each_pixel_turns_by_its_own_rotation():
    cams = [
        Camera.from_azimuth_tilt_roll(INTR, [k, 0.0, 10.0], 30.0 * k, -10.0 - k) for k in range(4)
    ]
    u = np.array([10.0, 200.0, 320.0, 600.0])
    v = np.array([20.0, 100.0, 240.0, 470.0])
    view = PosedView(
        INTR,
        u,
        v,
        np.stack([c.R_world_cam for c in cams]),
        np.stack([c.position_enu for c in cams]),
    )
    o, d, _, _ = posed_view_rays(view, 1.0)
    for k, c in enumerate(cams):
        ok, dk = c.pixel_to_ray([u[k]], [v[k]])
        np.testing.assert_allclose(d[k], dk[0], atol=1e-15)
        np.testing.assert_allclose(o[k], ok[0])


def test_shapes_and_pixels_are_checked():
    with pytest.raises(CameraError, match="needs R_world_cam"):
        PosedView(INTR, np.zeros(2), np.zeros(2), np.zeros((3, 3, 3)), np.zeros((2, 3)))
    view = PosedView(INTR, np.array([700.0]), np.array([0.0]), np.eye(3)[None], np.zeros((1, 3)))
    with pytest.raises(CameraError, match="outside"):
        posed_view_rays(view, 1.0)


def test_per_pixel_focal_lengths_are_the_ideal_zoom_per_pixel():
    rng = np.random.default_rng(4)
    k = 30
    hfov = rng.uniform(10.0, 45.0, k)
    u, v = rng.uniform(-0.5, 639.5, k), rng.uniform(-0.5, 479.5, k)
    rot = np.stack(
        [Camera.from_azimuth_tilt_roll(INTR, [0, 0, 5], a, -9.0).R_world_cam for a in 3 * hfov]
    )
    pos = rng.normal(0, 10, (k, 3))
    lenses = [intrinsics_for_hfov(INTR, h) for h in hfov]
    fx = np.array([lens.fx for lens in lenses])
    fy = np.array([lens.fy for lens in lenses])
    o, d, axes, sig = posed_view_rays(PosedView(INTR, u, v, rot, pos, fx, fy), 1.0)
    for i, lens in enumerate(lenses):
        one = PosedView(lens, u[i : i + 1], v[i : i + 1], rot[i : i + 1], pos[i : i + 1])
        o1, d1, a1, s1 = posed_view_rays(one, 1.0)
        np.testing.assert_allclose(d[i], d1[0], atol=1e-14)
        np.testing.assert_allclose(axes[i], a1[0], atol=1e-13)
        np.testing.assert_allclose(sig[i], s1[0], rtol=1e-12)


def test_a_zoom_wider_than_the_lens_can_invert_gives_nan_rays():
    strong = Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480, k1=-0.3)
    fx = np.full(2, 320.0 / np.tan(np.radians(60.0)))  # hfov 120 deg: past the fold
    with pytest.raises(CameraError, match="not invertible"):
        intrinsics_for_hfov(strong, 120.0)
    view = PosedView(
        strong, np.array([320.0, 0.0]), np.array([240.0, 0.0]), np.repeat(np.eye(3)[None], 2, 0),
        np.zeros((2, 3)), fx, fx,
    )  # fmt: skip
    _, d, _, _ = posed_view_rays(view, 1.0)
    assert np.isfinite(d[0]).all() and np.isnan(d[1]).all()
