"""Fixes at the pose of the moment: a head sweeping past targets on a flat DEM."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics, rotation_from_azimuth_tilt_roll
from demtrack.core.camera.pose_series import PoseSample, PoseSeries, camera_at
from demtrack.core.camera.zoom_lens import ZoomEntry, ZoomTable, ideal_focal_px
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geolocation.fix_builder import FIX_REASONS, build_fixes
from demtrack.core.site.folder import Sensor, load_site, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking import Detection

T0 = 1.8e9
FRAME = LocalFrame(40.3556, -79.6225, 331.0)
INTR = Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480)
HEAD_ENU = (0.0, -150.0, 20.0)
NO_OFFSET = {"vehicle": 0.0, "human": 0.0}


def flat_site(root, *, active=True, zoom=None, latency=0.0, intr=INTR):
    root.mkdir(parents=True, exist_ok=True)
    grid = GridSpec(-200.0, 200.0, 2.0, 200, 200)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(root / "dem.tif")
    ptz = Sensor(
        "ptz", "ptz", PanTiltHead(HEAD_ENU, 10.0, intr), 0.0, -7.0,
        active=active, zoom=zoom, pose_latency_s=latency,
    )  # fmt: skip
    fixed = Sensor("fixed", "fixed", PanTiltHead((30.0, -160.0, 15.0), 0.0, INTR), 0.0, -8.0)
    doc = site_manifest("flat", FRAME, [ptz, fixed], root, orthophoto=None, roads=None)
    (root / "site.json").write_text(json.dumps(doc))
    return load_site(root)


def sweep(n=41, dt=0.1):
    """Pan -20 -> +20 deg, tilt -8 -> -6 deg, hfov 40 -> 30 deg over 4 s."""
    t = T0 + dt * np.arange(n)
    s = (t - T0) / (dt * (n - 1))
    return PoseSeries.from_arrays(t, -20 + 40 * s, -8 + 2 * s, hfov_deg=40 - 10 * s)


def ground_point(pan, tilt, hfov, u, v, position=HEAD_ENU):
    """Independent: the ideal lens at hfov, the levelled head's rotation, a flat z = 0."""
    f = 0.5 * INTR.width / math.tan(math.radians(hfov) / 2)
    d_cam = np.array([(u - INTR.cx) / f, (v - INTR.cy) / f, 1.0])
    r = rotation_from_azimuth_tilt_roll(10.0 + pan, tilt, 0.0)
    d = r @ d_cam
    c = np.asarray(position, dtype=float)
    return c + d * (c[2] / -d[2])


def detections_between_samples(times, u=319.5, v=300.0):
    half = 20.0
    return [Detection(t, "ptz", (u - half, v - 30.0, u + half, v), "vehicle") for t in times]


def test_a_sweeping_head_gives_the_ground_point_of_each_moment(tmp_path):
    site = flat_site(tmp_path / "s")
    series = sweep()
    times = T0 + 0.05 + 0.1 * np.arange(38) + 0.013  # between samples
    dets = detections_between_samples(times)
    fixes, report = build_fixes(site, dets, poses={"ptz": series}, foot_offset_m=NO_OFFSET)
    assert report.n_fixes == len(dets) and report.counts["no_pose"] == 0
    s = (times - T0) / 4.0
    for f, k in zip(fixes, range(len(dets)), strict=True):
        want = ground_point(-20 + 40 * s[k], -8 + 2 * s[k], 40 - 10 * s[k], 319.5, 300.0)
        np.testing.assert_allclose(f.hits_enu[0], want, atol=2e-3)
        np.testing.assert_allclose(f.origin_enu, HEAD_ENU)
    # The stored pose (pan 0, tilt -7, the calibrated lens) puts them metres off.
    stale, _ = build_fixes(
        replace(site, sensors={**site.sensors, "ptz": replace(site.sensors["ptz"], active=False)}),
        dets,
        foot_offset_m=NO_OFFSET,
    )
    err = [np.linalg.norm(a.hits_enu[0] - b.hits_enu[0]) for a, b in zip(stale, fixes, strict=True)]
    assert min(err) > 5.0
    # A sensor not marked active but given a series is geolocated at its poses too.
    passive = replace(
        site, sensors={**site.sensors, "ptz": replace(site.sensors["ptz"], active=False)}
    )
    again, _ = build_fixes(passive, dets, poses={"ptz": series}, foot_offset_m=NO_OFFSET)
    for a, b in zip(again, fixes, strict=True):
        np.testing.assert_array_equal(a.hits_enu, b.hits_enu)


def test_detections_without_a_close_pose_are_no_pose(tmp_path):
    site = flat_site(tmp_path / "s")
    series = sweep()
    times = [T0 - 1.0, T0 + 0.05, T0 + 4.1, T0 + 4.5]  # before, inside, within gap, beyond
    dets = detections_between_samples(times)
    fixes, report = build_fixes(site, dets, poses={"ptz": series})
    assert [f.detection_index for f in fixes] == [1, 2]
    assert report.counts["no_pose"] == 2
    assert FIX_REASONS.index("no_pose") == FIX_REASONS.index("time_backwards") + 1
    assert "no_pose=2" in report.summary()
    # An active sensor with no series at all: nothing is geolocated at its stored pose.
    fixes, report = build_fixes(site, dets)
    assert fixes == [] and report.counts["no_pose"] == 4


def test_fixed_sensors_are_untouched_by_poses_of_others(tmp_path):
    site = flat_site(tmp_path / "s")
    fixed = [Detection(T0 + 0.1 * k, "fixed", (300, 250, 340, 300 + k), "human") for k in range(5)]
    alone, rep_alone = build_fixes(site, fixed)
    dets = fixed + detections_between_samples([T0 + 0.05, T0 + 0.15])
    mixed, rep = build_fixes(site, dets, poses={"ptz": sweep()})
    assert rep.n_fixes == 7 and rep_alone.n_fixes == 5
    for a, b in zip(alone, mixed[:5], strict=True):
        np.testing.assert_array_equal(a.hits_enu, b.hits_enu)
        np.testing.assert_array_equal(a.hit_cov_en_m2, b.hit_cov_en_m2)


def test_latency_is_the_sensors_setting(tmp_path):
    series = sweep()
    t = T0 + 1.234
    dets = detections_between_samples([t])
    site = flat_site(tmp_path / "a", latency=0.08)
    (fix,), _ = build_fixes(site, dets, poses={"ptz": series}, foot_offset_m=NO_OFFSET)
    s = (t + 0.08 - T0) / 4.0
    want = ground_point(-20 + 40 * s, -8 + 2 * s, 40 - 10 * s, 319.5, 300.0)
    np.testing.assert_allclose(fix.hits_enu[0], want, atol=2e-3)


def test_zoom_table_lens_and_zooms_outside_it(tmp_path):
    # A table of ideal lenses from 32 to 41 deg: the sweep's late zooms (< 32) fall outside.
    zoom = ZoomTable(
        tuple(
            ZoomEntry(h, ideal_focal_px(640, h), ideal_focal_px(640, h), 319.5, 239.5)
            for h in (32.0, 36.0, 41.0)
        )
    )
    site = flat_site(tmp_path / "s", zoom=zoom)
    times = T0 + np.array([0.05, 1.55, 3.55])  # hfov 39.9, 36.1, 31.1 deg
    fixes, report = build_fixes(
        site, detections_between_samples(times), poses={"ptz": sweep()}, foot_offset_m=NO_OFFSET
    )
    assert [f.detection_index for f in fixes] == [0, 1] and report.counts["no_pose"] == 1
    s = (times[1] - T0) / 4.0
    want = ground_point(-20 + 40 * s, -8 + 2 * s, 40 - 10 * s, 319.5, 300.0)
    np.testing.assert_allclose(fixes[1].hits_enu[0], want, atol=2e-3)


def test_a_moving_platform_uses_its_position_and_attitude(tmp_path):
    site = flat_site(tmp_path / "s")
    head = site.sensors["ptz"].head
    t = T0 + 0.1 * np.arange(11)
    s = t - T0
    pos = np.column_stack([-20 + 10 * s, -150 + 3 * s, 40 + s])
    ypr = np.column_stack([30 + 5 * s, 2 * s, -3 + s])
    series = PoseSeries.from_arrays(t, 5 * s, -15 + s, position_enu=pos, platform_ypr_deg=ypr)
    q = T0 + np.array([0.05, 0.42, 0.97])
    dets = detections_between_samples(q, u=200.0, v=310.0)
    fixes, report = build_fixes(site, dets, poses={"ptz": series}, foot_offset_m=NO_OFFSET)
    assert report.n_fixes == 3
    for k, f in enumerate(fixes):
        sk = q[k] - T0
        # Slerp between two attitudes on one axis-ish path differs from linear Euler angles
        # by far less than this test's tolerance over 0.1 s; the pose is built directly.
        pose = PoseSample(
            q[k], 5 * sk, -15 + sk,
            position_enu=tuple(pos[0] + (pos[1] - pos[0]) * sk / 0.1),
            platform_ypr_deg=(30 + 5 * sk, 2 * sk, -3 + sk),
        )  # fmt: skip
        cam = camera_at(head, pose)
        o, d = cam.pixel_to_ray([200.0], [310.0])
        want = o[0] + d[0] * (o[0, 2] / -d[0, 2])
        np.testing.assert_allclose(f.origin_enu, pose.position_enu, atol=1e-4)  # float32
        np.testing.assert_allclose(f.hits_enu[0], want, atol=5e-3)


@pytest.mark.parametrize("gap", [0.0, 0.05])
def test_the_sensors_gap_setting(tmp_path, gap):
    site = flat_site(tmp_path / "s")
    site = replace(
        site, sensors={**site.sensors, "ptz": replace(site.sensors["ptz"], max_pose_gap_s=gap)}
    )
    _, report = build_fixes(site, detections_between_samples([T0 + 0.03]), poses={"ptz": sweep()})
    assert report.counts["no_pose"] == (1 if gap < 0.03 else 0)


def test_a_zoom_the_lens_cannot_invert_at_a_pixel_is_no_pose(tmp_path):
    strong = Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480, k1=-0.3)
    site = flat_site(tmp_path / "s", intr=strong)
    series = PoseSeries.from_arrays([T0, T0 + 1.0], [0.0, 0.0], [-30.0, -30.0], hfov_deg=[120, 120])
    dets = [
        Detection(T0 + 0.1, "ptz", (300.0, 200.0, 340.0, 260.0), "vehicle"),  # near the axis
        Detection(T0 + 0.2, "ptz", (0.0, 400.0, 10.0, 479.0), "vehicle"),  # a far corner
    ]
    fixes, report = build_fixes(site, dets, poses={"ptz": series})
    assert [f.detection_index for f in fixes] == [0] and report.counts["no_pose"] == 1
