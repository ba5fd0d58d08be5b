"""KML/KMZ and GeoPackage track writers, read back by xml.etree, zipfile, pyogrio, ogrinfo."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import subprocess
import zipfile
from datetime import UTC, datetime
from xml.etree import ElementTree as ET

import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import shapely

from demtrack.core.io.track_io import (
    GPKG_APPLICATION_ID,
    GX_NS,
    KML_NS,
    HeightModel,
    write_tracks_gpkg,
    write_tracks_kml,
    write_tracks_kmz,
)
from demtrack.core.tracking.types import Track, TrackPoint

EPOCH = datetime(2024, 5, 1, 12, 0, 0, tzinfo=UTC)
Q = f"{{{KML_NS}}}"
G = f"{{{GX_NS}}}"
OGRINFO = shutil.which("ogrinfo")


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


def _gx_tracks(placemark):
    return placemark.findall(f"{G}MultiTrack/{G}Track")


def test_kml_has_a_gx_track_per_run_with_when_and_absolute_coords(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.kml"
    write_tracks_kml(path, tracks, to_geodetic, epoch=EPOCH)
    root = ET.parse(path).getroot()
    assert root.tag == f"{Q}kml"
    doc_desc = root.findtext(f"{Q}Document/{Q}description")
    assert "no geoid model" in doc_desc and "2024-05-01T12:00:00.000Z" in doc_desc
    marks = root.findall(f"{Q}Document/{Q}Placemark")
    assert [m.findtext(f"{Q}name") for m in marks] == ["track 3", "track 7"]
    car = marks[0]
    data = {d.get("name"): d.findtext(f"{Q}value") for d in car.iter(f"{Q}Data")}
    assert data["track_id"] == "3" and data["class"] == "vehicle" and data["sensors"] == "a,b"
    assert json.loads(data["gaps"]) == [[1.0, 4.0]]
    assert data["altitude"].startswith("ellipsoidal")
    assert car.findtext(f"{Q}TimeSpan/{Q}begin") == "2024-05-01T12:00:00.000Z"
    assert car.findtext(f"{Q}TimeSpan/{Q}end") == "2024-05-01T12:00:04.500Z"
    multi = car.find(f"{G}MultiTrack")
    assert multi.findtext(f"{G}interpolate") == "0"  # nothing drawn across the gap
    # The gap (1 s .. 4 s) splits the car into two gx:Tracks: points 0-2 and 3-4.
    runs = [[0, 1, 2], [3, 4]]
    gxts = _gx_tracks(car)
    assert len(gxts) == 2
    for gxt, run in zip(gxts, runs, strict=True):
        # Schema order: altitudeMode first, then every <when>, then every <gx:coord>.
        tags = [c.tag for c in gxt]
        assert tags == [f"{Q}altitudeMode"] + [f"{Q}when"] * len(run) + [f"{G}coord"] * len(run)
        assert gxt.findtext(f"{Q}altitudeMode") == "absolute"
        whens = [w.text for w in gxt.findall(f"{Q}when")]
        want_t = [tracks[0].points[i].t_s for i in run]
        got_t = [
            (
                datetime.strptime(w, "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=UTC) - EPOCH
            ).total_seconds()
            for w in whens
        ]
        assert got_t == want_t
        got = [tuple(map(float, c.text.split())) for c in gxt.findall(f"{G}coord")]
        assert got == [_lonlath(tracks[0].points[i]) for i in run]  # lon lat alt
    one = _gx_tracks(marks[1])
    assert len(one) == 1 and len(one[0].findall(f"{G}coord")) == 1


def test_kml_altitudes_are_orthometric_with_a_geoid_model(tmp_path):
    path = tmp_path / "t.kml"
    write_tracks_kml(path, _tracks(), to_geodetic, heights=HeightModel.constant_undulation(-33.0))
    root = ET.parse(path).getroot()
    alts = [float(c.text.split()[2]) for c in root.iter(f"{G}coord")]
    want = [_lonlath(p)[2] + 33.0 for t in _tracks() for p in t.points]
    assert alts == pytest.approx(want, abs=1e-9)
    assert "orthometric" in root.findtext(f"{Q}Document/{Q}description")


def test_kmz_holds_the_same_kml(tmp_path):
    kml, kmz = tmp_path / "t.kml", tmp_path / "t.kmz"
    write_tracks_kml(kml, _tracks(), to_geodetic, epoch=EPOCH)
    write_tracks_kmz(kmz, _tracks(), to_geodetic, epoch=EPOCH)
    with zipfile.ZipFile(kmz) as zf:
        assert zf.namelist() == ["doc.kml"]
        assert zf.read("doc.kml").decode() == kml.read_text()
    again = tmp_path / "u.kmz"
    write_tracks_kmz(again, _tracks(), to_geodetic, epoch=EPOCH)
    assert again.read_bytes() == kmz.read_bytes()  # the bytes depend on the tracks only


@pytest.mark.skipif(OGRINFO is None, reason="needs ogrinfo (Debian gdal-bin)")
def test_kml_gx_tracks_read_by_gdal_libkml(tmp_path):
    path = tmp_path / "t.kml"
    write_tracks_kml(path, _tracks(), to_geodetic, epoch=EPOCH)
    run = subprocess.run(
        [OGRINFO, "-ro", "-al", str(path)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "ERROR" not in run.stderr, run.stderr
    assert "using driver `LIBKML' successful" in run.stdout  # the driver that knows gx:Track
    lines = re.findall(r"MULTILINESTRING Z \((.*)\)", run.stdout)
    assert len(lines) == 2, run.stdout
    first = re.findall(r"\(([^()]*)\)", lines[0])
    got = [[tuple(float(x) for x in c.split()) for c in part.split(",")] for part in first]
    car = _tracks()[0].points
    np.testing.assert_allclose(got[0], [_lonlath(p) for p in car[:3]], atol=1e-9)
    np.testing.assert_allclose(got[1], [_lonlath(p) for p in car[3:]], atol=1e-9)


def test_gpkg_layers_read_by_pyogrio_with_spatial_index(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpkg"
    write_tracks_gpkg(path, tracks, to_geodetic, epoch=EPOCH)
    assert [tuple(x) for x in pyogrio.list_layers(path)] == [
        ("tracks", "MultiLineString Z"),
        ("track_points", "Point Z"),
    ]
    info = pyogrio.read_info(path, layer="tracks")
    assert info["features"] == 2 and info["crs"] == "EPSG:4979"
    assert info["capabilities"]["fast_spatial_filter"]  # the R-tree index
    meta, _, geoms, fields = pyogrio.raw.read(path, layer="tracks")
    cols = dict(zip(meta["fields"], fields, strict=True))
    assert list(cols["track_id"]) == [3, 7] and list(cols["class"]) == ["vehicle", "human"]
    assert list(cols["n_segments"]) == [2, 1] and json.loads(cols["gaps"][0]) == [[1.0, 4.0]]
    assert cols["time_end_utc"][0] == np.datetime64("2024-05-01T12:00:04.500")
    car = shapely.from_wkb(geoms[0])
    assert car.geom_type == "MultiLineString" and car.has_z
    pts = tracks[0].points
    np.testing.assert_array_equal(
        shapely.get_coordinates(car.geoms[0], include_z=True), [_lonlath(p) for p in pts[:3]]
    )
    np.testing.assert_array_equal(
        shapely.get_coordinates(car.geoms[1], include_z=True), [_lonlath(p) for p in pts[3:]]
    )
    person = shapely.from_wkb(geoms[1])
    np.testing.assert_array_equal(
        shapely.get_coordinates(person, include_z=True), [_lonlath(tracks[1].points[0])] * 2
    )
    meta, _, geoms, fields = pyogrio.raw.read(path, layer="track_points")
    cols = dict(zip(meta["fields"], fields, strict=True))
    assert len(geoms) == 6 and list(cols["segment"]) == [0, 0, 0, 1, 1, 0]
    assert np.all(np.isnan(cols["elevation_m"].astype(float)))  # no geoid model: null
    got = shapely.get_coordinates(shapely.from_wkb(geoms), include_z=True)
    np.testing.assert_array_equal(got, [_lonlath(p) for t in tracks for p in t.points])
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA application_id").fetchone()[0] == GPKG_APPLICATION_ID
    ext = conn.execute(
        "SELECT table_name FROM gpkg_extensions WHERE extension_name = 'gpkg_rtree_index'"
    ).fetchall()
    assert sorted(r[0] for r in ext) == ["track_points", "tracks"]
    assert conn.execute("SELECT COUNT(*) FROM rtree_tracks_geom").fetchone()[0] == 2
    desc = conn.execute("SELECT description FROM gpkg_contents WHERE table_name='tracks'")
    assert "ellipsoid" in desc.fetchone()[0]
    conn.close()


@pytest.mark.skipif(OGRINFO is None, reason="needs ogrinfo (Debian gdal-bin)")
def test_gpkg_is_read_by_ogrinfo(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpkg"
    write_tracks_gpkg(path, tracks, to_geodetic, epoch=EPOCH)
    run = subprocess.run(
        [OGRINFO, "-ro", "-al", "-q", str(path)], capture_output=True, text=True, check=True
    )
    assert "ERROR" not in run.stderr and "Warning" not in run.stderr, run.stderr
    out = run.stdout
    summary = subprocess.run(
        [OGRINFO, "-ro", "-so", str(path), "tracks"], capture_output=True, text=True, check=True
    ).stdout
    assert "Geometry: 3D Multi Line String" in summary and "Feature Count: 2" in summary
    assert re.search(r"track_id \(Integer(64)?\) = 3", out) and "class (String) = vehicle" in out
    assert "time_end_utc (DateTime) = 2024/05/01 12:00:04.5" in out  # UTC, ms
    assert len(re.findall(r"POINT Z \(", out)) == 6
    sql = subprocess.run(
        [OGRINFO, "-ro", "-q", str(path), "-sql", "SELECT HasSpatialIndex('tracks', 'geom')"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert re.search(r"= 1\b", sql), sql


def test_gpkg_replaces_an_existing_file_and_accepts_no_tracks(tmp_path):
    path = tmp_path / "t.gpkg"
    path.write_text("not a database")
    write_tracks_gpkg(path, [], to_geodetic)
    assert pyogrio.read_info(path, layer="tracks")["features"] == 0
    assert pyogrio.read_info(path, layer="track_points")["features"] == 0
