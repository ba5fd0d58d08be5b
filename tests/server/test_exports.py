"""``/api/tracks/export``: each format read back by a reader of its own, against ``/api/tracks``.

Readers: gpxpy (GPX), GDAL through pyogrio and ``ogrinfo`` (GeoPackage, CSV, GPX, KML via
LIBKML), :mod:`xml.etree` (KML ``gx:Track``), :mod:`zipfile` (KMZ), :mod:`json` (GeoJSON).
The oracle is ``GET /api/tracks`` with the same filters: its points, split by hand at its
gaps.
"""

from __future__ import annotations

import io
import json
import re
import shutil
import struct
import subprocess
import zipfile
from datetime import UTC, datetime, timedelta
from types import SimpleNamespace
from xml.etree import ElementTree as ET

import gpxpy
import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import shapely
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app, post_in_time_batches, scenario_records

from demtrack.core.io.track_io import GX_NS, KML_NS, HeightModel
from demtrack.core.site.folder import load_site
from demtrack.server.site_info import geoid_grid_path
from demtrack.server.track_export import export_bytes, site_heights, time_base

pytestmark = pytest.mark.timeout(600)
OGRINFO = shutil.which("ogrinfo")
EPOCH = "2024-05-01T12:00:00Z"
T0 = datetime(2024, 5, 1, 12, tzinfo=UTC)
Q, G = f"{{{KML_NS}}}", f"{{{GX_NS}}}"


@pytest.fixture(scope="module")
def fed(sample_site_dir, tmp_path_factory, module_store_kw):
    """A server that ingested the first 40 s of the vehicle run, 0.5 s per batch."""
    site = load_site(sample_site_dir)
    recs = scenario_records(site, "vehicle-run", 40.0)
    app = make_app(sample_site_dir, tmp_path_factory.mktemp("exp"), **module_store_kw)
    with TestClient(app) as c:
        post_in_time_batches(c, recs)
        yield c


def _tracks(c):
    r = c.get("/api/tracks", headers=AUTH)
    assert r.status_code == 200
    return r.json()["tracks"]


def _export(c, fmt, **params):
    r = c.get("/api/tracks/export", headers=AUTH, params={"format": fmt, "epoch": EPOCH, **params})
    assert r.status_code == 200, r.text
    return r


def _runs(body, key=("lon_deg", "lat_deg", "h_m")):
    """Indices of the body's runs between gaps, split by hand (the oracle)."""
    pts, runs = body["points"], []
    for k, p in enumerate(pts):
        if k == 0 or any(a <= pts[k - 1]["t_s"] and p["t_s"] <= b for a, b in body["gaps"]):
            runs.append([])
        runs[-1].append(k)
    return runs


def _egm96_n(lat_deg, lon_deg):
    """EGM96 undulation N (m) read straight from PROJ's ``egm96_15.gtx``, bilinear.

    The reader is this function (the .gtx layout: big-endian lat0, lon0, dlat, dlon as
    doubles, rows and columns as int32, then float32 rows south to north); None without
    the grid.
    """
    grid = geoid_grid_path()
    if grid is None:
        return None
    raw = grid.read_bytes()
    lat0, lon0, dlat, dlon = struct.unpack(">4d", raw[:32])
    rows, cols = struct.unpack(">2i", raw[32:40])
    n = np.frombuffer(raw[40:], dtype=">f4").reshape(rows, cols)
    y = (lat_deg - lat0) / dlat
    x = ((lon_deg - lon0) % 360.0) / dlon
    i, j = int(np.floor(y)), int(np.floor(x))
    fy, fx = y - i, x - j
    return float(
        n[i, j] * (1 - fy) * (1 - fx)
        + n[i, j + 1] * (1 - fy) * fx
        + n[i + 1, j] * fy * (1 - fx)
        + n[i + 1, j + 1] * fy * fx
    )


def _sea(p):
    """The oracle's sea-level height of a stored point: h - N(EGM96), h without the grid."""
    n = _egm96_n(p["lat_deg"], p["lon_deg"])
    return p["h_m"] if n is None else p["h_m"] - n


def _xyz(body, run):
    return [
        (body["points"][i]["lon_deg"], body["points"][i]["lat_deg"], body["points"][i]["h_m"])
        for i in run
    ]


def test_the_sample_run_has_a_gap_to_check(fed):
    tracks = _tracks(fed)
    assert tracks and any(len(_runs(t)) > 1 for t in tracks), "need a track with a gap"


def test_gpx_read_by_gpxpy_and_gdal(fed, tmp_path):
    tracks = _tracks(fed)
    gpx = gpxpy.parse(_export(fed, "gpx").text)
    assert [t.name for t in gpx.tracks] == [f"track {t['id']}" for t in tracks]
    assert EPOCH.replace("Z", ".000Z") in gpx.description
    assert ("EGM96" if geoid_grid_path() else "no geoid model") in gpx.description
    for trk, body in zip(gpx.tracks, tracks, strict=True):
        runs = _runs(body)
        assert [len(s.points) for s in trk.segments] == [len(r) for r in runs]  # gaps split
        for seg, run in zip(trk.segments, runs, strict=True):
            for p, i in zip(seg.points, run, strict=True):
                want = body["points"][i]
                assert (p.longitude, p.latitude) == (want["lon_deg"], want["lat_deg"])
                # <ele> is above sea level: h - N(EGM96) within 1 cm of the grid read here.
                assert p.elevation == pytest.approx(_sea(want), abs=0.01)
                assert p.time == T0 + timedelta(milliseconds=round(want["t_s"] * 1000))
    path = tmp_path / "t.gpx"
    path.write_bytes(_export(fed, "gpx").content)
    meta, _, geoms, _ = pyogrio.raw.read(path, layer="track_points")
    n = sum(len(t["points"]) for t in tracks)
    assert len(geoms) == n and "ele" in meta["fields"] and "time" in meta["fields"]


def test_kml_gx_tracks_hold_when_and_coords_per_point(fed):
    tracks = _tracks(fed)
    root = ET.fromstring(_export(fed, "kml").content)
    marks = root.findall(f"{Q}Document/{Q}Placemark")
    assert len(marks) == len(tracks)
    for pm, body in zip(marks, tracks, strict=True):
        gxts = pm.findall(f"{G}MultiTrack/{G}Track")
        runs = _runs(body)
        assert len(gxts) == len(runs)
        for gxt, run in zip(gxts, runs, strict=True):
            whens = [w.text for w in gxt.findall(f"{Q}when")]
            coords = [tuple(map(float, c.text.split())) for c in gxt.findall(f"{G}coord")]
            assert len(whens) == len(coords) == len(run)
            assert [c[:2] for c in coords] == [c[:2] for c in _xyz(body, run)]
            alts = [c[2] for c in coords]
            assert alts == pytest.approx([_sea(body["points"][i]) for i in run], abs=0.01)
            assert gxt.findtext(f"{Q}altitudeMode") == "absolute"
            got_t = [datetime.fromisoformat(w.replace("Z", "+00:00")) for w in whens]
            assert got_t == [
                T0 + timedelta(milliseconds=round(body["points"][i]["t_s"] * 1000)) for i in run
            ]
    kmz = _export(fed, "kmz")
    assert kmz.headers["content-type"] == "application/vnd.google-earth.kmz"
    with zipfile.ZipFile(io.BytesIO(kmz.content)) as zf:
        assert zf.read("doc.kml") == _export(fed, "kml").content


def test_geopackage_read_by_pyogrio_and_ogrinfo_with_spatial_index(fed, tmp_path):
    tracks = _tracks(fed)
    path = tmp_path / "t.gpkg"
    path.write_bytes(_export(fed, "gpkg").content)
    info = pyogrio.read_info(path, layer="tracks")
    assert info["features"] == len(tracks) and info["geometry_type"] == "MultiLineString Z"
    assert info["capabilities"]["fast_spatial_filter"]
    _, _, geoms, fields = pyogrio.raw.read(path, layer="tracks")
    assert list(fields[0]) == [t["id"] for t in tracks]
    for g, body in zip(geoms, tracks, strict=True):
        lines = shapely.from_wkb(g).geoms
        runs = _runs(body)
        assert len(lines) == len(runs)
        for line, run in zip(lines, runs, strict=True):
            want = _xyz(body, run)
            want = want if len(want) > 1 else want * 2
            np.testing.assert_allclose(shapely.get_coordinates(line, include_z=True), want, atol=0)
    n = sum(len(t["points"]) for t in tracks)
    assert pyogrio.read_info(path, layer="track_points")["features"] == n
    if OGRINFO:
        out = subprocess.run(
            [OGRINFO, "-ro", "-q", str(path), "-sql", "SELECT HasSpatialIndex('tracks','geom')"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert re.search(r"= 1\b", out), out
        so = subprocess.run(
            [OGRINFO, "-ro", "-so", str(path), "tracks"], capture_output=True, text=True, check=True
        ).stdout
        assert f"Feature Count: {len(tracks)}" in so and "3D Multi Line String" in so


def test_csv_read_by_gdal_with_longitude_latitude(fed, tmp_path):
    tracks = _tracks(fed)
    path = tmp_path / "t.csv"
    path.write_bytes(_export(fed, "csv").content)
    meta, _, geoms, fields = pyogrio.raw.read(
        path,
        X_POSSIBLE_NAMES="longitude",
        Y_POSSIBLE_NAMES="latitude",
        Z_POSSIBLE_NAMES="h_wgs84_m",
        AUTODETECT_TYPE="YES",
    )
    got = shapely.get_coordinates(shapely.from_wkb(geoms), include_z=True)
    want = [xyz for t in tracks for xyz in _xyz(t, range(len(t["points"])))]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    cols = dict(zip(meta["fields"], fields, strict=True))
    segs = [k for t in tracks for k, run in enumerate(_runs(t)) for _ in run]
    assert [int(s) for s in cols["segment"]] == segs
    assert cols["time_utc"][0] is not None


def test_geojson_lines_follow_the_runs(fed):
    tracks = _tracks(fed)
    feats = _export(fed, "geojson").json()["features"]
    for f, body in zip(feats, tracks, strict=True):
        want = [_xyz(body, r) if len(r) > 1 else _xyz(body, r) * 2 for r in _runs(body)]
        assert [[tuple(c) for c in line] for line in f["geometry"]["coordinates"]] == want
        assert f["properties"]["times_utc"][0].startswith("2024-05-01T12:")


def test_track_ids_choose_the_tracks_and_the_epoch_defaults_to_unix(fed):
    tracks = _tracks(fed)
    one = tracks[-1]["id"]
    r = fed.get(f"/api/tracks/export?format=geojson&track={one}", headers=AUTH)
    feats = r.json()["features"]
    assert [f["properties"]["track_id"] for f in feats] == [one]
    props = feats[0]["properties"]
    assert props["epoch_utc"] == "1970-01-01T00:00:00.000Z" and props["wall_clock"] is False
    assert "session seconds" in props["time"]
    assert fed.get("/api/tracks/export?track=x", headers=AUTH).status_code == 422


def test_sea_level_heights_use_the_site_geoid(fed):
    """Without the EGM96 grid: the site's stated N, else none (ellipsoidal, declared)."""
    assert not site_heights(SimpleNamespace(geoid_undulation_m=0.0), egm96=False).orthometric
    heights = site_heights(SimpleNamespace(geoid_undulation_m=-33.0), egm96=False)
    bodies = _tracks(fed)
    gpx = gpxpy.parse(export_bytes("gpx", bodies, None, time_base(None), heights).decode())
    eles = [p.elevation for t in gpx.tracks for s in t.segments for p in s.points]
    assert eles == pytest.approx([p["h_m"] + 33.0 for b in bodies for p in b["points"]])
    doc = json.loads(export_bytes("geojson", bodies, None, None, heights))
    z = [c[2] for f in doc["features"] for line in f["geometry"]["coordinates"] for c in line]
    assert set(z) <= {p["h_m"] for b in bodies for p in b["points"]}  # GeoJSON stays ellipsoidal
    assert (
        isinstance(heights, HeightModel)
        and "orthometric" in doc["features"][0]["properties"]["height"]
    )
