"""KML and GeoPackage track writers, checked by XML parsing and by GDAL's ``ogrinfo``."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import struct
import subprocess
from datetime import UTC, datetime
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import shapely

from demtrack.core.errors import TrackingError
from demtrack.core.io.track_io import (
    GPKG_APPLICATION_ID,
    KML_NS,
    write_tracks_gpkg,
    write_tracks_kml,
)
from demtrack.core.tracking.types import Track, TrackPoint

EPOCH = datetime(2024, 5, 1, 12, 0, 0, tzinfo=UTC)
Q = f"{{{KML_NS}}}"


def to_geodetic(e, n, u):
    """A stand-in converter (not geodesy): linear, lat and lon clearly different."""
    return 45.0 + n / 111_000.0, 7.0 + e / 78_000.0, 100.0 + u


def _tracks():
    t = [0.0, 0.5, 1.0, 4.0, 4.5]
    pts = [TrackPoint(ti, [10.0 * ti, -3.0 * ti, 0.25 * k], ("a",), (k,)) for k, ti in enumerate(t)]
    car = Track(3, "vehicle", pts, {"a", "b"}, [(1.0, 4.0)])
    person = Track(7, "human", [TrackPoint(2.0, [1.0, 2.0, 3.0], ("b",), (9,))], {"b"})
    return [car, person]


def _lonlath(p):
    lat, lon, h = to_geodetic(*p.p_enu)
    return lon, lat, h


def test_kml_places_a_line_per_run_in_lon_lat_alt_order(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.kml"
    write_tracks_kml(path, tracks, to_geodetic, epoch=EPOCH)
    root = ET.parse(path).getroot()
    assert root.tag == f"{Q}kml"
    marks = root.findall(f"{Q}Document/{Q}Placemark")
    assert [m.findtext(f"{Q}name") for m in marks] == ["track 3", "track 7"]
    car = marks[0]
    data = {d.get("name"): d.findtext(f"{Q}value") for d in car.iter(f"{Q}Data")}
    assert data["track_id"] == "3" and data["class"] == "vehicle" and data["sensors"] == "a,b"
    assert json.loads(data["gaps"]) == [[1.0, 4.0]]
    assert car.findtext(f"{Q}TimeSpan/{Q}begin") == "2024-05-01T12:00:00.000Z"
    assert car.findtext(f"{Q}TimeSpan/{Q}end") == "2024-05-01T12:00:04.500Z"
    # The gap (1 s .. 4 s) splits the car into two LineStrings: points 0-2 and 3-4.
    lines = car.findall(f"{Q}MultiGeometry/{Q}LineString")
    assert len(lines) == 2
    runs = [[0, 1, 2], [3, 4]]
    for line, run in zip(lines, runs, strict=True):
        assert line.findtext(f"{Q}altitudeMode") == "clampToGround"
        got = [tuple(map(float, c.split(","))) for c in line.findtext(f"{Q}coordinates").split()]
        want = [_lonlath(tracks[0].points[i]) for i in run]
        assert got == want  # KML: lon,lat,alt
        assert all(44 < lat < 46 and 6 < lon < 8 for lon, lat, _ in got)
    # The one-point track is a Point.
    point = marks[1].find(f"{Q}MultiGeometry/{Q}Point/{Q}coordinates")
    assert tuple(map(float, point.text.split(","))) == _lonlath(tracks[1].points[0])


def test_kml_without_epoch_and_bad_mode(tmp_path):
    path = tmp_path / "t.kml"
    write_tracks_kml(path, _tracks(), to_geodetic, altitude_mode="absolute")
    root = ET.parse(path).getroot()
    assert root.find(f".//{Q}TimeSpan") is None
    assert {e.text for e in root.iter(f"{Q}altitudeMode")} == {"absolute"}
    with pytest.raises(TrackingError, match="altitude mode"):
        write_tracks_kml(path, _tracks(), to_geodetic, altitude_mode="sky")


def test_gpkg_header_tables_and_binary_geometry(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpkg"
    write_tracks_gpkg(path, tracks, to_geodetic, epoch=EPOCH)
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA application_id").fetchone()[0] == GPKG_APPLICATION_ID
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 10300
    srs = {r[0] for r in conn.execute("SELECT srs_id FROM gpkg_spatial_ref_sys")}
    assert srs == {4326, 0, -1}
    cols = conn.execute(
        "SELECT table_name, geometry_type_name, srs_id, z, m FROM gpkg_geometry_columns"
        " ORDER BY table_name"
    ).fetchall()
    assert cols == [("track_points", "POINT", 4326, 1, 0), ("tracks", "LINESTRING", 4326, 1, 0)]
    blob, tid, times = conn.execute(
        "SELECT geom, track_id, time_end_utc FROM tracks WHERE track_id = 3"
    ).fetchone()
    assert tid == 3 and times == "2024-05-01T12:00:04.500Z"
    # GeoPackage binary header, decoded by hand (spec clause 2.1.3).
    assert blob[:2] == b"GP" and blob[2] == 0
    flags = blob[3]
    assert flags & 1 == 1 and (flags >> 1) & 0b111 == 1  # little endian, xy envelope
    (srs_id,) = struct.unpack("<i", blob[4:8])
    x0, x1, y0, y1 = struct.unpack("<4d", blob[8:40])
    line = shapely.from_wkb(blob[40:])
    want = np.array([_lonlath(p) for p in tracks[0].points])
    assert srs_id == 4326 and line.has_z
    np.testing.assert_array_equal(shapely.get_coordinates(line, include_z=True), want)
    assert (x0, x1, y0, y1) == (
        want[:, 0].min(),
        want[:, 0].max(),
        want[:, 1].min(),
        want[:, 1].max(),
    )
    every = np.array([_lonlath(p) for t in tracks for p in t.points])
    contents = conn.execute("SELECT min_x, max_y FROM gpkg_contents WHERE table_name='tracks'")
    assert contents.fetchone() == (every[:, 0].min(), every[:, 1].max())
    assert conn.execute("SELECT COUNT(*) FROM track_points").fetchone()[0] == 6
    conn.close()


@pytest.mark.skipif(shutil.which("ogrinfo") is None, reason="needs ogrinfo (Debian gdal-bin)")
def test_gpkg_is_read_by_ogrinfo(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpkg"
    write_tracks_gpkg(path, tracks, to_geodetic, epoch=EPOCH)
    run = subprocess.run(
        ["ogrinfo", "-ro", "-al", "-q", str(path)], capture_output=True, text=True, check=True
    )
    assert "ERROR" not in run.stderr and "Warning" not in run.stderr, run.stderr
    out = run.stdout
    summary = subprocess.run(
        ["ogrinfo", "-ro", "-so", str(path)], capture_output=True, text=True, check=True
    ).stdout
    assert "tracks (3D Line String)" in summary and "track_points (3D Point)" in summary
    lines = re.findall(r"LINESTRING Z \(([^)]*)\)", out)
    assert len(lines) == 2
    for text, track in zip(lines, tracks, strict=True):
        got = np.array([[float(x) for x in c.split()] for c in text.split(",")])
        want = np.array([_lonlath(p) for p in track.points])
        if len(want) == 1:
            want = np.vstack([want, want])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert re.search(r"track_id \(Integer(64)?\) = 3", out) and "class (String) = vehicle" in out
    assert "time_end_utc (DateTime) = 2024/05/01 12:00:04.5" in out  # UTC, ms
    points = re.findall(r"POINT Z \(([^)]*)\)", out)
    assert len(points) == 6
    np.testing.assert_allclose(
        [float(x) for x in points[-1].split()], _lonlath(tracks[1].points[0]), atol=1e-9
    )


def test_gpkg_replaces_an_existing_file_and_accepts_no_tracks(tmp_path):
    path = tmp_path / "t.gpkg"
    path.write_text("not a database")
    write_tracks_gpkg(path, [], to_geodetic)
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT COUNT(*) FROM tracks").fetchone()[0] == 0
    assert conn.execute("SELECT min_x FROM gpkg_contents").fetchall() == [(None,), (None,)]
