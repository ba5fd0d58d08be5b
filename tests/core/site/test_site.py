from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from demtrack.core.camera.pantilt import LandmarkReading, PanTiltHead
from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.errors import SiteError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geolocation.roads import RoadNetwork
from demtrack.core.site.folder import Sensor, load_site, site_manifest
from demtrack.core.site.road_io import write_roads_geojson
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

FRAME = LocalFrame(40.3556, -79.6225, 331.0)


def make_site(root: Path, *, roads: bool = True) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    grid = GridSpec(-50.0, 50.0, 1.0, 100, 100)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(root / "dem.tif")
    head = PanTiltHead(
        [0.0, -40.0, 10.0],
        5.0,
        Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480),
        (LandmarkReading("post", 0.0, 40.0, -5.0), LandmarkReading("gate", 40.0, -40.0, 85.0)),
    )
    sensors = [Sensor("cam1", "Test camera", head, 0.0, -20.0)]
    if roads:
        net = RoadNetwork.from_coordinates([np.array([[-40.0, -13.0], [40.0, -13.0]])], ["main"])
        write_roads_geojson(root / "roads.geojson", net, FRAME)
    doc = site_manifest(
        "test", FRAME, sensors, root, orthophoto=None, roads="roads.geojson" if roads else None
    )
    (root / "site.json").write_text(json.dumps(doc))
    return root


def test_load_round_trips_frame_dem_sensor_and_roads(tmp_path):
    site = load_site(make_site(tmp_path / "s"))
    assert site.frame == FRAME
    assert site.dem.grid.shape == (100, 100)
    cam = site.sensor("cam1").camera
    np.testing.assert_allclose(cam.position_enu, [0.0, -40.0, 10.0])
    az, tilt, _ = cam.azimuth_tilt_roll_deg()
    assert az == pytest.approx(5.0) and tilt == pytest.approx(-20.0)
    assert site.roads.names == ("main",)
    np.testing.assert_allclose(
        np.asarray(site.roads.lines[0].coords), [[-40, -13], [40, -13]], atol=1e-4
    )  # 9 decimal degrees in the file: ~0.1 mm
    assert site.sensor("cam1").head.calibrate().yaw_deg == pytest.approx(5.0, abs=1e-9)


def test_geolocator_uses_the_sites_dem_and_roads(tmp_path):
    site = load_site(make_site(tmp_path / "s"))
    cam = site.sensor("cam1").camera
    (g,) = site.geolocator().geolocate(cam, [319.5], [239.5], rule="road")
    # Camera 10 m up looking 20 deg down along az 5 deg: ground at 10 / tan(20 deg).
    d = 10.0 / np.tan(np.radians(20.0))
    expect = [d * np.sin(np.radians(5.0)), -40.0 + d * np.cos(np.radians(5.0)), 0.0]
    np.testing.assert_allclose(g.hits[0].p_enu, expect, atol=1e-3)
    assert g.road is not None and g.road.p_enu[1] == pytest.approx(-13.0, abs=1e-4)
    assert g.best is g.road


def test_site_without_roads_has_none(tmp_path):
    assert load_site(make_site(tmp_path / "s", roads=False)).roads is None


def edit_manifest(root: Path, **changes) -> Path:
    doc = json.loads((root / "site.json").read_text())
    doc.update(changes)
    (root / "site.json").write_text(json.dumps(doc))
    return root


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"format": "other"}, "format must be 'demtrack.site'"),
        ({"version": 9}, "unsupported version 9"),
        ({"dem": "../dem.tif"}, "points outside the site folder"),
        ({"dem": "missing.tif"}, "'dem' file is missing"),
        ({"frame": {"lat_deg": 1.0}}, "local frame is missing lon_deg, h_m"),
        ({"sensors": {"a": 1}}, "'sensors' must be a list"),
        ({"sensors": [{"name": "x"}]}, "sensor 0 needs a non-empty string 'id'"),
        ({"geoid_undulation_m": "x"}, "'geoid_undulation_m' must be a finite number"),
    ],
)
def test_malformed_manifest_gives_one_line_site_error(tmp_path, changes, message):
    root = edit_manifest(make_site(tmp_path / "s"), **changes)
    with pytest.raises(SiteError, match=message) as err:
        load_site(root)
    assert "\n" not in str(err.value)


def test_duplicate_sensor_and_bad_head_are_named(tmp_path):
    root = make_site(tmp_path / "s")
    doc = json.loads((root / "site.json").read_text())
    edit_manifest(root, sensors=doc["sensors"] * 2)
    with pytest.raises(SiteError, match="sensor id 'cam1' appears twice"):
        load_site(root)
    bad = dict(doc["sensors"][0], head={"format": "demtrack.pantilt", "version": 1})
    edit_manifest(root, sensors=[bad])
    with pytest.raises(SiteError, match="sensor 'cam1'.*missing keys"):
        load_site(root)


def test_unknown_sensor_lists_the_known_ones(tmp_path):
    site = load_site(make_site(tmp_path / "s"))
    with pytest.raises(SiteError, match="unknown sensor 'cam9'; this site has: cam1"):
        site.sensor("cam9")


def test_missing_folder_manifest_and_bad_json(tmp_path):
    with pytest.raises(SiteError, match="site folder not found"):
        load_site(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SiteError, match="no site.json"):
        load_site(tmp_path / "empty")
    root = make_site(tmp_path / "s")
    (root / "site.json").write_text("{not json")
    with pytest.raises(SiteError, match="not valid JSON"):
        load_site(root)


def test_bad_road_file_is_reported_as_site_error(tmp_path):
    root = make_site(tmp_path / "s")
    (root / "roads.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    with pytest.raises(SiteError, match="has no line features"):
        load_site(root)
