"""Pose latency from data: a wobbling head following a car, telemetry 80 ms late."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.camera.pose_series import PoseSample, PoseSeries, camera_at
from demtrack.core.errors import PoseError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geolocation.pose_latency import estimate_pose_latency, track_jitter
from demtrack.core.site.folder import Sensor, load_site, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking import Detection

T0 = 1.8e9
INTR = Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480)
HEAD = PanTiltHead([0.0, -150.0, 20.0], 0.0, INTR)
TRUE_LATENCY_S = 0.08


def flat_site(root):
    root.mkdir(parents=True, exist_ok=True)
    grid = GridSpec(-200.0, 200.0, 2.0, 200, 200)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(root / "dem.tif")
    sensors = [Sensor("ptz", "ptz", HEAD, 0.0, -7.0, active=True)]
    doc = site_manifest("flat", LocalFrame(40.0, -79.0, 300.0), sensors, root, orthophoto=None)
    doc.pop("roads", None)
    (root / "site.json").write_text(json.dumps(doc))
    return load_site(root)


def target(s):
    return np.array([-60.0 + 20.0 * s, 3.0 * s, 0.0])


def true_pose(s):
    """The head aims at the car, with a following error that wobbles (pan 2 deg, tilt 1 deg)."""
    v = target(s) - HEAD.position_enu
    az = math.degrees(math.atan2(v[0], v[1]))
    el = math.degrees(math.atan2(v[2], math.hypot(v[0], v[1])))
    pan = az + 2.0 * math.sin(2 * math.pi * 0.7 * s)
    tilt = el + 1.0 * math.sin(2 * math.pi * 0.5 * s + 1.0)
    return pan, tilt


def scenario(rng):
    # Telemetry at 30 Hz, each stamped 80 ms after the moment it describes.
    tau = T0 + np.arange(-30, 7 * 30) / 30.0
    poses = [true_pose(x - TRUE_LATENCY_S - T0) for x in tau]
    series = PoseSeries.from_arrays(tau, [p[0] for p in poses], [p[1] for p in poses])
    dets = []
    for k in range(150):
        t = T0 + 0.04 * k
        cam = camera_at(HEAD, PoseSample(t, *true_pose(t - T0)))
        u, v, _ = cam.project(target(t - T0))
        u, v = u[0] + rng.normal(0, 0.2), v[0] + rng.normal(0, 0.2)
        dets.append(Detection(t, "ptz", (u - 10.0, v - 20.0, u + 10.0, v), "vehicle"))
    return series, dets


def test_recovers_an_80_ms_latency(tmp_path):
    site = flat_site(tmp_path / "s")
    series, dets = scenario(np.random.default_rng(0))
    est = estimate_pose_latency(site, dets, series, "ptz")
    assert est.latency_s == pytest.approx(TRUE_LATENCY_S, abs=0.01)
    assert est.n_detections == 150
    # The curve: its minimum is the estimate, and zero latency is visibly worse.
    assert est.jitter == est.curve_jitter.min()
    at_zero = est.curve_jitter[np.argmin(np.abs(est.curve_latency_s))]
    assert at_zero > 10 * est.jitter
    assert np.all(np.diff(est.curve_latency_s) > 0)
    assert re.match(r"pose latency \+[78]\d\.\d ms \(track jitter", est.summary())


def test_track_jitter_oracles():
    t = np.linspace(0.0, 3.0, 31) ** 1.2  # uneven steps
    line = np.column_stack([2.0 * t + 1.0, -3.0 * t])
    assert track_jitter(t, line, trim=0.0) == pytest.approx(0.0, abs=1e-18)
    # Constant acceleration (1.5, -2) m/s^2: the uneven-step second difference is exact.
    para = np.column_stack([0.75 * t**2, -1.0 * t**2])
    assert track_jitter(t, para, trim=0.0) == pytest.approx(1.5**2 + 2.0**2, rel=1e-9)
    # One wild point is trimmed away.
    bad = para.copy()
    bad[15] += 50.0
    assert track_jitter(t, bad, trim=0.15) == pytest.approx(6.25, rel=1e-9)
    assert track_jitter(t, bad, trim=0.0) > 100


def test_too_few_detections_and_bad_ranges(tmp_path):
    site = flat_site(tmp_path / "s")
    series, dets = scenario(np.random.default_rng(1))
    with pytest.raises(PoseError, match="at least 5 detections"):
        estimate_pose_latency(site, dets[:4], series, "ptz")
    with pytest.raises(PoseError, match="search_s"):
        estimate_pose_latency(site, dets, series, "ptz", search_s=(0.5, -0.5))
