"""``demtrack track --poses``: a PTZ head's telemetry file drives geolocation end to end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from demtrack.cli import main
from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.camera.pose_series import PoseSample, PoseSeries, camera_at
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.io.detections import write_detections_csv
from demtrack.core.io.pose_io import write_poses_csv, write_poses_jsonl
from demtrack.core.site.folder import Sensor, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.tracking import Detection

T0 = 1.8e9
HEAD = PanTiltHead([0.0, -150.0, 20.0], 0.0, Intrinsics(800.0, 800.0, 319.5, 239.5, 640, 480))
LATENCY = 0.08


def pose_at(s):
    """Following a car on y = 3 s; the pan wobbles as the head corrects."""
    v = np.array([-60.0 + 20.0 * s, 3.0 * s, 0.0]) - HEAD.position_enu
    az = math.degrees(math.atan2(v[0], v[1])) + 2.0 * math.sin(2 * math.pi * 0.7 * s)
    el = math.degrees(math.atan2(v[2], math.hypot(v[0], v[1])))
    return az, el


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("ptz")
    site = root / "site"
    site.mkdir()
    grid = GridSpec(-200.0, 200.0, 2.0, 200, 200)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(site / "dem.tif")
    sensors = [Sensor("ptz", "ptz", HEAD, 0.0, -7.0, active=True)]
    doc = site_manifest("flat", LocalFrame(40.0, -79.0, 300.0), sensors, site, orthophoto=None)
    doc.pop("roads")
    (site / "site.json").write_text(json.dumps(doc))
    tau = T0 + np.arange(-15, 6 * 15) / 15.0
    series = PoseSeries.from_arrays(tau, *np.array([pose_at(x - LATENCY - T0) for x in tau]).T)
    dets = []
    for k in range(100):
        t = T0 + 0.05 * k
        s = t - T0
        cam = camera_at(HEAD, PoseSample(t, *pose_at(s)))
        u, v, _ = cam.project([-60.0 + 20.0 * s, 3.0 * s, 0.0])
        dets.append(Detection(t, "ptz", (u[0] - 10, v[0] - 20, u[0] + 10, v[0]), "vehicle"))
    dets.append(Detection(T0 + 30.0, "ptz", (300, 200, 320, 260), "vehicle"))  # no pose then
    write_detections_csv(root / "d.csv", dets)
    write_poses_csv(root / "p.csv", {"ptz": series})
    write_poses_jsonl(root / "p.jsonl", {"ptz": series})
    return root


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_track_with_poses_counts_no_pose_and_tracks_the_car(capsys, files):
    out = files / "t.geojson"
    status, text, _ = run(
        capsys, "track", "--site", files / "site", "--detections", files / "d.csv",
        "--poses", files / "p.csv", "--method", "kalman", "-o", out,
    )  # fmt: skip
    assert status == 0, text
    assert "105 of 105 pose samples accepted" in text
    assert "100 fixes from 101 detections" in text and "no_pose=1" in text
    doc = json.loads(out.read_text())
    assert [f for f in doc["features"] if f["properties"]["kind"] == "track"]
    # Without telemetry the active head has no pose at all: nothing is geolocated.
    status, text, _ = run(
        capsys, "track", "--site", files / "site", "--detections", files / "d.csv",
        "--method", "kalman", "-o", files / "none.geojson",
    )  # fmt: skip
    assert status == 0 and "0 fixes from 101 detections" in text and "no_pose=101" in text


def test_estimate_latency_prints_and_uses_it(capsys, files):
    status, text, err = run(
        capsys, "track", "--site", files / "site", "--detections", files / "d.csv",
        "--poses", files / "p.jsonl", "--estimate-latency", "ptz",
        "--method", "kalman", "-o", files / "t.csv",
    )  # fmt: skip
    assert status == 0, err
    line = next(x for x in text.splitlines() if x.startswith("ptz: pose latency"))
    ms = float(line.split("latency ")[1].split(" ms")[0])
    assert abs(ms - 80.0) < 10.0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--poses", "bad.csv"], "pose CSV lacks column(s) tilt_deg"),
        (["--poses", "p.csv", "--poses", "p.jsonl"], "sensor 'ptz' has poses in two"),
        (["--poses", "p.txt"], "unknown pose file type"),
        (["--estimate-latency", "ptz"], "no poses for that sensor"),
    ],
)
def test_bad_pose_input_is_one_line(capsys, files, extra, message):
    (files / "bad.csv").write_text("sensor,t,pan_deg\nptz,1,2\n")
    argv = [files / a if a.startswith(("p.", "bad")) else a for a in extra]
    status, _, err = run(
        capsys, "track", "--site", files / "site", "--detections", files / "d.csv",
        *argv, "-o", files / "x.csv",
    )  # fmt: skip
    assert status == 2 and message in err and err.count("\n") == 1
