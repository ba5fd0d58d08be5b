"""A sensor's PTZ fields in site.json: written only when not default, read back, checked."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.camera.zoom_lens import ZoomEntry, ZoomTable
from demtrack.core.errors import SiteError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.site.folder import Sensor, load_site, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

FRAME = LocalFrame(40.3556, -79.6225, 331.0)
HEAD = PanTiltHead([0.0, -40.0, 10.0], 5.0, Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480))
ZOOM = ZoomTable(
    (ZoomEntry(60.0, 560.0, 560.0, 320.0, 240.0), ZoomEntry(10.0, 3600, 3600, 321, 239))
)


def write_site(root, sensors):
    root.mkdir(parents=True, exist_ok=True)
    grid = GridSpec(-50.0, 50.0, 1.0, 100, 100)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(root / "dem.tif")
    doc = site_manifest("t", FRAME, sensors, root, orthophoto=None, roads=None)
    (root / "site.json").write_text(json.dumps(doc))
    return doc


def test_defaults_are_not_written_and_fields_round_trip(tmp_path):
    plain = Sensor("cam0", "plain", HEAD, 0.0, -20.0)
    ptz = replace(
        plain,
        id="ptz",
        active=True,
        zoom=ZOOM,
        pose_latency_s=0.08,
        max_pose_gap_s=0.5,
        slew_limits={"pan_rate_deg_s": 60.0, "tilt_min_deg": -60.0},
    )
    doc = write_site(tmp_path / "s", [plain, ptz])
    entry0, entry1 = doc["sensors"]
    assert set(entry0) == {"id", "name", "head", "pan_deg", "tilt_deg"}
    assert entry1["active"] is True and entry1["zoom_table"] == ZOOM.to_list()
    assert (entry1["pose_latency_s"], entry1["max_pose_gap_s"]) == (0.08, 0.5)
    site = load_site(tmp_path / "s")
    got = site.sensor("ptz")
    assert (got.active, got.zoom, got.pose_latency_s, got.max_pose_gap_s) == (
        True, ZOOM, 0.08, 0.5,
    )  # fmt: skip
    assert got.slew_limits == {"pan_rate_deg_s": 60.0, "tilt_min_deg": -60.0}
    p = site.sensor("cam0")
    assert (p.active, p.zoom, p.pose_latency_s, p.max_pose_gap_s, p.slew_limits) == (
        False, None, 0.0, 0.2, None,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"active": "yes"}, "'active' must be true or false"),
        ({"zoom_table": [{"hfov_deg": 400, "fx": 1, "fy": 1, "cx": 0, "cy": 0}]}, "zoom_table"),
        ({"pose_latency_s": "fast"}, "pose_latency_s"),
        ({"max_pose_gap_s": -1.0}, "max_pose_gap_s"),
        ({"slew_limits": {"pan_rate_deg_s": float("nan")}}, "slew_limits"),
        ({"slew_limits": [1, 2]}, "slew_limits"),
    ],
)
def test_bad_fields_are_one_line_site_errors(tmp_path, change, match):
    doc = write_site(tmp_path / "s", [Sensor("cam0", "c", HEAD, 0.0, -20.0)])
    doc["sensors"][0].update(change)
    (tmp_path / "s" / "site.json").write_text(json.dumps(doc))
    with pytest.raises(SiteError, match=match) as err:
        load_site(tmp_path / "s")
    assert "\n" not in str(err.value) and "'cam0'" in str(err.value)
