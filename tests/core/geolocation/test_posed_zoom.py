"""A lens per pixel from a zoom table: the same rays as the exact lens of each zoom."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from demtrack.core.camera.lens import radial_fold_radius
from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.camera.pose_series import PoseSample, PoseSeries, camera_at
from demtrack.core.camera.zoom_lens import ZoomEntry, ZoomTable, fold_radii, ideal_focal_px
from demtrack.core.errors import CameraError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.geolocation.posed_rays import PosedView, posed_view_rays
from demtrack.core.site.folder import Sensor, load_site, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking import Detection

BASE = Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480)
# Distortion, aspect and principal point all move with the zoom; fx is not the ideal one.
TABLE = ZoomTable(
    (
        ZoomEntry(8.0, 1.02 * ideal_focal_px(640, 8.0), 1.03 * ideal_focal_px(640, 8.0),
                  322.0, 236.0, 0.01, 0.0, 1e-4, -2e-4),
        ZoomEntry(20.0, 0.99 * ideal_focal_px(640, 20.0), ideal_focal_px(640, 20.0),
                  317.0, 241.5, -0.06, 0.02, -3e-4, 1e-4, 0.004),
        ZoomEntry(45.0, ideal_focal_px(640, 45.0), 1.01 * ideal_focal_px(640, 45.0),
                  312.0, 246.0, -0.15, 0.05, 5e-4, 3e-4, -0.01, 0.002),
    )
)  # fmt: skip
T0 = 1.8e9


def _angle(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def test_fold_radii_are_radial_fold_radius_for_each_lens():
    rng = np.random.default_rng(0)
    k = rng.normal(0.0, 0.1, (200, 4)) * rng.integers(0, 2, (200, 4))  # some zero terms
    k[:5] = 0.0
    k[5:10, 3] = 1e-30  # negligible leading terms are dropped, as there
    got = fold_radii(*k.T)
    want = np.array([radial_fold_radius(*row) for row in k])
    np.testing.assert_array_equal(np.isinf(got), np.isinf(want))
    fin = np.isfinite(want)
    assert fin.sum() > 50
    np.testing.assert_allclose(got[fin], want[fin], rtol=1e-12)


def test_pixel_lenses_are_intrinsics_at_each_zoom():
    hfov = np.concatenate([np.linspace(8.0, 45.0, 401), [8.0, 20.0, 45.0, 7.99, 45.01, np.nan]])
    lenses = TABLE.pixel_lenses(hfov, BASE)
    assert lenses.valid.tolist() == [True] * 404 + [False] * 3
    for k, h in enumerate(hfov[:404]):
        want = TABLE.intrinsics_at(float(h), BASE)
        got = (lenses.fx[k], lenses.fy[k], lenses.cx[k], lenses.cy[k], *lenses.coeffs[k])
        np.testing.assert_allclose(got, (want.fx, want.fy, want.cx, want.cy, *want.lens_coeffs),
                                   rtol=1e-13, atol=1e-17)  # fmt: skip
        assert lenses.fold_radius[k] == pytest.approx(want.fold_radius, rel=1e-12)
    assert np.isnan(lenses.fx[404:]).all()


def test_a_zoom_whose_lens_folds_in_the_image_is_refused_like_intrinsics():
    # Radial only: the fold check settles invertibility exactly, for both.
    table = ZoomTable(
        (ZoomEntry(30.0, 1108.5, 1108.5, 319.5, 239.5), ZoomEntry(90.0, 320.0, 320.0, 319.5,
                                                                  239.5, -0.6))
    )  # fmt: skip
    hfov = np.linspace(30.0, 90.0, 241)
    lenses = table.pixel_lenses(hfov, BASE)
    exact = []
    for h in hfov:
        try:
            table.intrinsics_at(float(h), BASE)
            exact.append(True)
        except CameraError:
            exact.append(False)
    assert lenses.valid.tolist() == exact
    assert 0 < sum(exact) < len(exact)  # the sweep crosses the limit


def test_rays_equal_the_exact_lens_of_each_pixels_zoom():
    # The oracle: one view of 600 pixels, each at its own zoom, rotation and centre,
    # against 600 one-pixel views with the exact Intrinsics of that zoom.
    rng = np.random.default_rng(1)
    n = 600
    hfov = np.sort(rng.uniform(8.0, 45.0, n))
    hfov[:3] = (8.0, 20.0, 45.0)
    u, v = rng.uniform(-0.5, 639.5, n), rng.uniform(-0.5, 479.5, n)
    cams = [
        Camera.from_azimuth_tilt_roll(BASE, rng.normal(0, 50, 3), a, t, r)
        for a, t, r in zip(rng.uniform(0, 360, n), rng.uniform(-40, 0, n), rng.normal(0, 2, n),
                           strict=True)
    ]  # fmt: skip
    rot = np.stack([c.R_world_cam for c in cams])
    pos = np.stack([c.position_enu for c in cams])
    lenses = TABLE.pixel_lenses(hfov, BASE)
    o, d, axes, sig = posed_view_rays(PosedView(BASE, u, v, rot, pos, lenses=lenses), 1.3)
    assert np.isfinite(d).all()
    for k in range(n):
        intr = TABLE.intrinsics_at(float(hfov[k]), BASE)
        view = PosedView(intr, u[k : k + 1], v[k : k + 1], rot[k : k + 1], pos[k : k + 1])
        ok, dk, ak, sk = posed_view_rays(view, 1.3)
        np.testing.assert_array_equal(o[k], ok[0])
        assert _angle(d[k], dk[0]) < 1e-9
        assert np.all(_angle(axes[k], ak[0]) < 1e-7)
        np.testing.assert_allclose(sig[k], sk[0], rtol=1e-7)


def test_a_view_checks_its_pixel_lenses():
    lenses = TABLE.pixel_lenses(np.array([10.0, 50.0]), BASE)
    with pytest.raises(CameraError, match="valid pixel lenses"):
        PosedView(BASE, np.zeros(2), np.zeros(2), np.stack([np.eye(3)] * 2), np.zeros((2, 3)),
                  lenses=lenses)  # fmt: skip
    good = lenses.take(np.array([0]))
    with pytest.raises(CameraError, match="not both"):
        PosedView(BASE, np.zeros(1), np.zeros(1), np.eye(3)[None], np.zeros((1, 3)),
                  fx_px=np.ones(1), fy_px=np.ones(1), lenses=good)  # fmt: skip


def test_build_fixes_with_a_zoom_table_hits_the_exact_lens_ground_point(tmp_path):
    # A head zooming continuously (a new hfov every frame) over a flat DEM: each fix is the
    # exact lens's ray at that frame's pose, met with z = 0 (independent arithmetic).
    grid = GridSpec(-400.0, 400.0, 4.0, 200, 200)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(tmp_path / "dem.tif")
    head = PanTiltHead((0.0, -150.0, 20.0), 10.0, BASE)
    ptz = Sensor("ptz", "ptz", head, 0.0, -7.0, active=True, zoom=TABLE)
    doc = site_manifest("flat", LocalFrame(40.3, -79.6, 331.0), [ptz], tmp_path,
                        orthophoto=None, roads=None)  # fmt: skip
    (tmp_path / "site.json").write_text(json.dumps(doc))
    site = load_site(tmp_path)
    t = T0 + 0.04 * np.arange(101)
    s = (t - T0) / 4.0
    series = PoseSeries.from_arrays(t, -10 + 20 * s, -12 + 2 * s, hfov_deg=44 - 35 * s)
    q = T0 + 0.04 * np.arange(100) + 0.013
    rng = np.random.default_rng(2)
    uc, vb = rng.uniform(40, 600, 100), rng.uniform(300, 470, 100)
    dets = [Detection(tq, "ptz", (a - 10, b - 20, a + 10, b), "vehicle")
            for tq, a, b in zip(q, uc, vb, strict=True)]  # fmt: skip
    dets.append(Detection(T0 + 4.5, "ptz", (300, 300, 320, 320), "vehicle"))  # past the series
    fixes, report = build_fixes(site, dets, poses={"ptz": series},
                                foot_offset_m={"vehicle": 0.0})  # fmt: skip
    assert report.n_fixes == 100 and report.counts["no_pose"] == 1
    at = series.at(q)
    for k, f in enumerate(fixes):
        intr = TABLE.intrinsics_at(float(at.hfov_deg[k]), BASE)
        pose = PoseSample(q[k], float(at.pan_deg[k]), float(at.tilt_deg[k]))
        cam = camera_at(replace(head, intrinsics=intr), pose)
        o, d = cam.pixel_to_ray([uc[k]], [vb[k]])
        want = o[0] + d[0] * (o[0, 2] / -d[0, 2])
        np.testing.assert_allclose(f.hits_enu[0], want, atol=5e-3)  # float32 hits
