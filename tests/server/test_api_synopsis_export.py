"""``/api/tracks/export``, ``/api/synopsis`` and ``/api/events`` on a real ingest."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil
import subprocess
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app, post_in_time_batches, scenario_records

from demtrack.core.io.track_io import GPX_NS, GX_NS, KML_NS
from demtrack.core.site.folder import load_site
from demtrack.server.synopsis import synopsis, trajectory

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def fed(sample_site_dir, tmp_path_factory, module_store_kw):
    """A server that ingested the first 30 s of the vehicle run, 0.5 s per batch."""
    site = load_site(sample_site_dir)
    recs = scenario_records(site, "vehicle-run", 30.0)
    app = make_app(sample_site_dir, tmp_path_factory.mktemp("syn"), **module_store_kw)
    with TestClient(app) as c:
        post_in_time_batches(c, recs)
        yield c


def _runs(body):
    """The body's [lon, lat, h] per run between gaps (a one-point run twice), by hand."""
    pts, runs = body["points"], []
    for k, p in enumerate(pts):
        cut = k == 0 or any(a <= pts[k - 1]["t_s"] and p["t_s"] <= b for a, b in body["gaps"])
        if cut:
            runs.append([])
        runs[-1].append((p["lon_deg"], p["lat_deg"], p["h_m"]))
    return [r if len(r) > 1 else r * 2 for r in runs]


def _tracks(c, **params):
    r = c.get("/api/tracks", headers=AUTH, params=params)
    assert r.status_code == 200
    return r.json()["tracks"]


def test_export_formats_hold_the_listed_points(fed):
    tracks = _tracks(fed, t_from=5, t_to=25)
    assert tracks
    lonlath = [[(p["lon_deg"], p["lat_deg"], p["h_m"]) for p in t["points"]] for t in tracks]
    n_points = sum(len(t) for t in lonlath)

    r = fed.get("/api/tracks/export?format=geojson&t_from=5&t_to=25", headers=AUTH)
    assert r.status_code == 200 and r.headers["content-type"] == "application/geo+json"
    assert 'filename="tracks.geojson"' in r.headers["content-disposition"]
    feats = r.json()["features"]
    assert [f["properties"]["track_id"] for f in feats] == [t["id"] for t in tracks]
    for f, t in zip(feats, tracks, strict=True):
        # One line per run between gaps (a one-point run is its point twice).
        assert f["geometry"]["type"] == "MultiLineString"
        got = [[tuple(c) for c in line] for line in f["geometry"]["coordinates"]]
        assert got == _runs(t)

    r = fed.get("/api/tracks/export?format=csv&t_from=5&t_to=25", headers=AUTH)
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert len(rows) == n_points
    assert float(rows[0]["longitude"]) == lonlath[0][0][0]
    assert float(rows[0]["latitude"]) == lonlath[0][0][1]

    r = fed.get("/api/tracks/export?format=gpx&t_from=5&t_to=25", headers=AUTH)
    pts = ET.fromstring(r.content).iter(f"{{{GPX_NS}}}trkpt")
    assert sum(1 for _ in pts) == n_points

    r = fed.get("/api/tracks/export?format=kml&t_from=5&t_to=25", headers=AUTH)
    assert r.headers["content-type"] == "application/vnd.google-earth.kml+xml"
    root = ET.fromstring(r.content)
    q, gx = f"{{{KML_NS}}}", f"{{{GX_NS}}}"
    marks = root.findall(f"{q}Document/{q}Placemark")
    assert len(marks) == len(tracks)
    got = [
        tuple(float(x) for x in c.text.split())
        for g in marks[0].find(f"{gx}MultiTrack")
        for c in g.findall(f"{gx}coord")
    ]
    # lon lat in track order, runs concatenated (the sea-level alt: tests/server/test_exports.py)
    assert [c[:2] for c in got] == [c[:2] for c in lonlath[0]]


@pytest.mark.skipif(shutil.which("ogrinfo") is None, reason="needs ogrinfo (Debian gdal-bin)")
def test_geopackage_export_reads_back_with_ogrinfo(fed, tmp_path):
    tracks = _tracks(fed, **{"class": "vehicle"})
    r = fed.get("/api/tracks/export?format=gpkg&class=vehicle", headers=AUTH)
    assert r.status_code == 200 and r.content[:16] == b"SQLite format 3\x00"
    path = tmp_path / "t.gpkg"
    path.write_bytes(r.content)
    out = subprocess.run(
        ["ogrinfo", "-ro", "-al", "-q", str(path)], capture_output=True, text=True, check=True
    )
    assert "ERROR" not in out.stderr, out.stderr
    lines = re.findall(r"MULTILINESTRING Z \((.*)\)", out.stdout)
    assert len(lines) == len(tracks)
    for text, t in zip(lines, tracks, strict=True):
        parts = re.findall(r"\(([^()]*)\)", text)
        got = [[[float(x) for x in c.split()] for c in part.split(",")] for part in parts]
        want = _runs(t)
        assert [len(g) for g in got] == [len(w) for w in want]
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-8)
    n_points = sum(len(t["points"]) for t in tracks)
    assert len(re.findall(r"POINT Z \(", out.stdout)) == n_points


def test_export_rejects_bad_parameters(fed):
    assert fed.get("/api/tracks/export?format=shp", headers=AUTH).status_code == 422
    r = fed.get("/api/tracks/export?format=gpx&epoch=yesterday", headers=AUTH)
    assert r.status_code == 422 and "epoch" in r.json()["detail"]
    assert fed.get("/api/tracks/export?t_from=5&t_to=1", headers=AUTH).status_code == 422
    assert fed.get("/api/tracks/export").status_code == 401


def _body(points, gaps, tid=1):
    return {
        "id": tid,
        "cls": "human",
        "live": False,
        "sensors": sorted({s for p in points for s in p[1]}),
        "gaps": gaps,
        "points": [
            {
                "t_s": t,
                "e_m": 2.0 * t,
                "n_m": 0.0,
                "u_m": 1.0,
                "lat_deg": 40.0,
                "lon_deg": -79.0,
                "h_m": 1.0,
                "sensors": list(s),
                "detection_ids": [k],
            }
            for k, (t, s) in enumerate(points)
        ],
    }


def test_trajectory_split_into_tracked_parts_and_gaps():
    pts = [(0.0, ["a"]), (1.0, ["a"]), (2.0, ["a", "b"]), (6.0, ["c"]), (7.0, ["c"])]
    pts += [(20.0, ["c"]), (21.0, ["c"])]
    traj = trajectory(_body(pts, [[2.0, 6.0], [7.0, 20.0]]), step_s=1.0)
    kinds = [p["kind"] for p in traj["parts"]]
    assert kinds == ["tracked", "gap", "tracked", "gap", "tracked"]
    first, gap1, _, gap2, _ = traj["parts"]
    assert first["sensors"] == ["a", "b"] and first["n_points"] == 3
    spans = {s["sensor"]: (s["t_start_s"], s["t_end_s"]) for s in first["sensor_spans"]}
    assert spans == {"a": (0.0, 2.0), "b": (2.0, 2.0)}
    assert first["length_m"] == pytest.approx(4.0)
    assert (gap1["duration_s"], gap1["sensors_before"], gap1["sensors_after"]) == (
        4.0,
        ["a", "b"],
        ["c"],
    )
    assert gap1["handoff"] and gap1["distance_m"] == pytest.approx(8.0)
    assert not gap2["handoff"] and gap2["duration_s"] == 13.0  # lost and found by c
    assert (traj["n_gaps"], traj["n_handoffs"]) == (2, 1)
    assert traj["length_m"] == pytest.approx(2.0 * (2 + 1 + 1))  # the gaps are not path
    # durations add up: parts tile the trajectory
    assert sum(p["duration_s"] for p in traj["parts"]) == traj["duration_s"] == 21.0


def test_synopsis_events_follow_the_filters():
    bodies = [_body([(0.0, ["a"]), (1.0, ["a"])], [], 1), _body([(0.0, ["b"])], [], 2)]
    events = [
        {"id": 7, "kind": "loitering", "track_ids": [2]},
        {"id": 8, "kind": "rendezvous", "track_ids": [1, 9]},
    ]
    out = synopsis(bodies[:1], events, 0.0, 5.0, 1.0, filtered=True)
    assert [e["id"] for e in out["events"]] == [8]
    assert out["trajectories"][0]["event_ids"] == [8]
    out = synopsis(bodies, events, None, None, 1.0, filtered=False)
    assert out["events_by_kind"] == {"loitering": 1, "rendezvous": 1}
    assert out["by_class"] == {"human": 2}


def test_synopsis_endpoint_on_the_vehicle_run(fed):
    r = fed.get("/api/synopsis?t0=0&t1=30", headers=AUTH)
    assert r.status_code == 200, r.text
    syn = r.json()
    tracks = _tracks(fed, t_from=0, t_to=30)
    assert [t["track_id"] for t in syn["trajectories"]] == [t["id"] for t in tracks]
    for traj, t in zip(syn["trajectories"], tracks, strict=True):
        assert traj["n_points"] == len(t["points"])
        tracked = [p for p in traj["parts"] if p["kind"] == "tracked"]
        assert sum(p["n_points"] for p in tracked) == traj["n_points"]
        for a, b in zip(traj["parts"], traj["parts"][1:], strict=False):
            assert a["t_end_s"] == b["t_start_s"] and a["kind"] != b["kind"]
        for g in (p for p in traj["parts"] if p["kind"] == "gap"):
            assert any(g0 <= g["t_start_s"] and g["t_end_s"] <= g1 for g0, g1 in t["gaps"])
    kinds = {e["kind"] for e in syn["events"]}
    assert "track_confirmed" in kinds
    assert syn["n_trajectories"] == len(tracks)
    assert fed.get("/api/synopsis?t0=5&t1=1", headers=AUTH).status_code == 422
    assert fed.get("/api/synopsis?class=dog", headers=AUTH).status_code == 422
    assert "/api/synopsis" in fed.get("/openapi.json").json()["paths"]


def test_events_endpoint_filters(fed):
    every = fed.get("/api/events", headers=AUTH).json()["events"]
    starts = [e["t_start_s"] for e in every]
    assert every and starts == sorted(starts)
    confirmed = fed.get("/api/events?kind=track_confirmed", headers=AUTH).json()["events"]
    assert {e["track_ids"][0] for e in confirmed} == {t["id"] for t in _tracks(fed)}
    both = fed.get("/api/events?kind=track_confirmed&kind=handoff", headers=AUTH).json()
    assert {e["kind"] for e in both["events"]} <= {"track_confirmed", "handoff"}
    late = fed.get("/api/events?t_from=20&t_to=30", headers=AUTH).json()["events"]
    assert all(e["t_end_s"] >= 20 and e["t_start_s"] <= 30 for e in late)
    one = confirmed[0]["track_ids"][0]
    mine = fed.get(f"/api/events?track={one}", headers=AUTH).json()["events"]
    assert mine and all(one in e["track_ids"] for e in mine)
    assert fed.get("/api/events?kind=picnic", headers=AUTH).status_code == 422
    assert fed.get("/api/events?t_from=3&t_to=1", headers=AUTH).status_code == 422
    assert json.loads(fed.get("/api/events?limit=1", headers=AUTH).text)["events"] == every[:1]
