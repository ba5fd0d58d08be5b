"""Automatic zoom while following: a simulated head narrows on a target driving away.

The oracle is the camera model: the target's 4.5 m projected through the lens at the
head's *reported* pan, tilt and zoom (the zoom table's lens) spans a share of the image
width that must stay in the 5-14 % band once the zoom has caught up. The same run with
the band switched off holds the zoom, and the share falls out of the band (so the test
can fail).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from heads_helpers import T0, Clock, ScriptedTracks, active_site

from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.camera.zoom_control import ZoomBand, image_share, zoom_to_band
from demtrack.core.camera.zoom_lens import ideal_focal_px
from demtrack.core.errors import PoseError
from demtrack.core.site.folder import load_site
from demtrack.server.heads.config import active_head_configs, build_adapter
from demtrack.server.heads.controller import HeadController, HeadUnit


def test_the_band_rule():
    band = ZoomBand()
    assert zoom_to_band(30.0, 0.1, band, (3.0, 60.0)) == 30.0  # in the band: hold
    assert zoom_to_band(30.0, None, band, (3.0, 60.0)) == 30.0  # not measured: hold
    assert zoom_to_band(30.0, 0.02, band, (3.0, 60.0)) == pytest.approx(7.5)
    assert zoom_to_band(30.0, 0.32, band, (3.0, 60.0)) == 60.0  # held in the range
    assert zoom_to_band(30.0, 0.001, band, (3.0, 60.0)) == 3.0
    with pytest.raises(PoseError, match="zoom band"):
        ZoomBand(0.1, 0.14, 0.05)
    # A pinhole at 1000 px focal length: 4.5 m at 450 m is 10 px, of 1000.
    assert image_share(4.5, 450.0, 1000.0, 1000) == pytest.approx(0.01)


def drive_away(site, sid, r0=40.0, r1=520.0, duration_s=60.0):
    """A straight path along the head's stored line of sight, on the DEM (truth-like)."""
    sensor = site.sensor(sid)
    t = np.arange(0.0, duration_s + 0.01, 0.1)
    az = np.radians(sensor.head.mount_yaw_deg + sensor.pan_deg)
    r = r0 + (r1 - r0) * t / duration_s
    c = sensor.head.position_enu
    x, y = c[0] + r * np.sin(az), c[1] + r * np.cos(az)
    z = site.dem.sample(x, y)
    z = np.where(np.isfinite(z), z, c[2] - 10.0)
    return SimpleNamespace(t_s=t, p_enu=np.column_stack([x, y, z]))


def share_seen(site, sid, status, p_enu) -> float:
    """The target's 4.5 m across the line of sight, in the image at the reported pose."""
    sensor = site.sensor(sid)
    pose = PoseSample(status.t_s, status.pan_deg, status.tilt_deg, hfov_deg=status.hfov_deg)
    cam = camera_at(sensor.head, pose, sensor.zoom)
    p = np.asarray(p_enu, float) + [0.0, 0.0, 0.75]
    los = p - sensor.head.position_enu
    across = np.array([-los[1], los[0], 0.0]) / np.hypot(los[0], los[1])
    u = cam.project(np.stack([p - 2.25 * across, p + 2.25 * across]))[0]
    return abs(float(u[1] - u[0])) / sensor.head.intrinsics.width


def run(sample_site_dir, dest, band):
    clock = Clock()
    site0 = load_site(sample_site_dir)
    base = site0.sensor("cam1").head.intrinsics
    hfov_lens = float(np.degrees(2 * np.arctan(base.width / (2 * base.fx))))
    # A table whose principal point drifts with the zoom, from 4 deg to the lens's own.
    table = [
        {"hfov_deg": h, "fx": ideal_focal_px(base.width, h),
         "fy": ideal_focal_px(base.width, h) * base.fy / base.fx,
         "cx": base.cx + 3.0 * k, "cy": base.cy - 2.0 * k}
        for k, h in enumerate((4.0, 12.0, round(hfov_lens, 3)))
    ]  # fmt: skip
    entry = {"active": True, "head_adapter": {"kind": "sim"}, "zoom_table": table}
    site = load_site(active_site(sample_site_dir, dest, {"cam1": entry}))
    truth = drive_away(site, "cam1")
    units = [
        HeadUnit(c.sensor_id, build_adapter(site, c, clock), c.limits, c.adapter["kind"])
        for c in active_head_configs(site)
    ]
    ctl = HeadController(
        site, units, ScriptedTracks(truth, clock, end_s=61.0), None, period_s=0.1,
        clock=clock, zoom_band=band,
    )  # fmt: skip
    ctl.planner.clock = clock
    clock.t = T0 + 1.0
    ctl.tick()
    ctl.follow("cam1", 7)
    out = []
    for k in range(11, 600):
        clock.t = T0 + 0.1 * k
        ctl.tick()
        st = ctl.units["cam1"].status
        p = truth.p_enu[k]
        out.append((0.1 * k, st.hfov_deg, share_seen(site, "cam1", st, p), ctl.units["cam1"].mode))
    return out


def test_a_following_head_zooms_in_on_a_target_driving_away(sample_site_dir, tmp_path):
    rows = run(sample_site_dir, tmp_path / "zoom", ZoomBand())
    t, hfov, share, mode = (np.array(c) for c in zip(*rows, strict=True))
    assert set(mode) == {"follow"}
    # The field of view narrows as the range grows 13-fold (never widening on the way).
    assert hfov[-1] < 0.25 * hfov[0]
    assert np.all(np.diff(hfov) <= 1e-9)
    # In the band once settled; at its lower edge within 0.003, the gap between the
    # controller's range-based share and the projected one.
    settled = t > 8.0
    assert share[settled].min() >= 0.05 - 0.003 and share[settled].max() <= 0.14
    # Held between changes: the band rule does not chase the goal every tick.
    assert np.count_nonzero(np.diff(hfov) < -1e-9) < 0.3 * len(hfov)

    still = run(sample_site_dir, tmp_path / "still", None)
    hfov0, share0 = np.array([r[1] for r in still]), np.array([r[2] for r in still])
    assert np.ptp(hfov0) == 0.0 and share0[-1] < 0.05  # without the band, it falls out
