"""Real UTC times through the server (issue 27, item 4): ingest, API answers, exports.

A vehicle run is posted at real times (``time``: ISO 8601 with a +01:00 zone, and ``t``
relative to a batch ``epoch``); the oracle is Python's ``datetime`` arithmetic on the
scenario's own times. GPX is read back with gpxpy and GDAL, KML with ``xml.etree``,
GeoPackage with GDAL: every time is the real UTC one and every file says so.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta, timezone
from xml.etree import ElementTree as ET

import gpxpy
import pyogrio
import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app

from demtrack.core.io.times import format_utc
from demtrack.core.io.track_io import GX_NS, KML_NS
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario

pytestmark = pytest.mark.timeout(600)
T0 = datetime(2026, 12, 1, 14, 30, tzinfo=UTC)
T0_S = T0.timestamp()
PLUS1 = timezone(timedelta(hours=1))
UNTIL_S = 30.0


@pytest.fixture(scope="module")
def real(sample_site_dir, tmp_path_factory, module_store_kw):
    """A server fed the first 30 s of the vehicle run at 2026-12-01T14:30:00Z."""
    sc = make_scenario(load_site(sample_site_dir), "vehicle-run")
    dets = [d for d in sc.detections if d.t_s < UNTIL_S]
    app = make_app(sample_site_dir, tmp_path_factory.mktemp("real"), **module_store_kw)
    with TestClient(app) as c:
        for k in range(int(UNTIL_S / 0.5)):
            part = [d for d in dets if 0.5 * k <= d.t_s < 0.5 * (k + 1)]
            if not part:
                continue
            if k % 2:  # ISO 8601 with a zone, in place of t
                recs = [
                    {
                        "time": (T0 + timedelta(seconds=d.t_s)).astimezone(PLUS1).isoformat(),
                        "sensor": d.sensor,
                        "bbox": list(d.bbox),
                        "class": d.cls,
                    }
                    for d in part
                ]
                body = {"detections": recs}
            else:  # relative t after the batch's declared epoch
                recs = [
                    {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls}
                    for d in part
                ]
                body = {"detections": recs, "epoch": "2026-12-01T09:30:00-05:00"}
            r = c.post("/api/detections", headers=AUTH, json=body)
            assert r.status_code == 200 and r.json()["skipped"] == 0, r.text
        yield c, dets


def test_stored_times_are_the_real_ones(real):
    c, dets = real
    rows = c.get("/api/detections", headers=AUTH, params={"limit": 10_000}).json()
    assert len(rows) == len(dets)
    got = sorted(r["t"] for r in rows)
    want = sorted(T0_S + d.t_s for d in dets)
    assert max(abs(a - b) for a, b in zip(got, want, strict=True)) < 1e-6
    for r in rows[:50]:
        assert r["time_utc"] == format_utc(r["t"])
        parsed = datetime.fromisoformat(r["time_utc"].replace("Z", "+00:00"))
        assert abs(parsed.timestamp() - r["t"]) <= 0.0005


def test_track_points_and_events_carry_iso_times(real):
    c, _ = real
    tracks = c.get("/api/tracks", headers=AUTH).json()["tracks"]
    assert tracks
    for p in tracks[0]["points"]:
        assert p["time_utc"] == format_utc(p["t_s"]) and p["time_utc"].startswith(
            "2026-12-01T14:30:"
        )
    one = c.get(f"/api/tracks/{tracks[0]['id']}", headers=AUTH).json()["tracks"][0]
    assert one["points"][0]["time_utc"] == tracks[0]["points"][0]["time_utc"]
    events = c.get("/api/events", headers=AUTH).json()["events"]
    assert events
    for e in events:
        assert e["time_utc"] == format_utc(e["t_start_s"])
        assert e["end_time_utc"] == format_utc(e["t_end_s"])


def test_windows_take_iso_times_and_refuse_zoneless_ones(real):
    c, _ = real
    iso = c.get(
        "/api/tracks",
        headers=AUTH,
        params={"t_from": "2026-12-01T15:30:10+01:00", "t_to": "2026-12-01T14:30:20Z"},
    ).json()["tracks"]
    unix = c.get(
        "/api/tracks", headers=AUTH, params={"t_from": T0_S + 10, "t_to": T0_S + 20}
    ).json()["tracks"]
    assert iso == unix and iso
    assert all(T0_S + 10 <= p["t_s"] <= T0_S + 20 for tr in iso for p in tr["points"])
    for path, name in (("/api/tracks", "t_to"), ("/api/events", "t_to"), ("/api/synopsis", "t1")):
        r = c.get(path, headers=AUTH, params={name: "2026-12-01T14:30:20"})
        assert r.status_code == 422, (path, r.text)
        detail = r.json()["detail"]
        assert name in detail and "no zone" in detail and "\n" not in detail
    r = c.get("/api/tracks/export", headers=AUTH, params={"epoch": "2026-12-01T14:30:00"})
    assert r.status_code == 422 and "epoch" in r.json()["detail"]
    r = c.post(
        "/api/detections", headers=AUTH, json={"detections": [], "epoch": "2026-12-01 14:30"}
    )
    assert r.status_code == 422 and "epoch" in r.json()["detail"]


def _gdal_times(path, name):
    """GDAL's reading of a layer's DateTime column, as ISO 8601 UTC strings (ms)."""
    meta, _, _, fields = pyogrio.raw.read(path, layer="track_points", datetime_as_string=True)
    values = fields[list(meta["fields"]).index(name)]
    out = set()
    for v in values:
        when = datetime.fromisoformat(str(v).replace("Z", "+00:00"))
        when = when if when.tzinfo else when.replace(tzinfo=UTC)
        out.add(format_utc(when.timestamp()))
    return out


def test_gpx_kml_gpkg_times_are_real_utc(real, tmp_path):
    c, _ = real
    tracks = c.get("/api/tracks", headers=AUTH).json()["tracks"]
    want = {format_utc(p["t_s"]) for tr in tracks for p in tr["points"]}

    gpx_bytes = c.get("/api/tracks/export?format=gpx", headers=AUTH).content
    gpx = gpxpy.parse(gpx_bytes.decode())
    got = {
        pt.time.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
        for trk in gpx.tracks
        for seg in trk.segments
        for pt in seg.points
    }
    assert got == want
    assert "times are UTC" in gpx.description
    (tmp_path / "t.gpx").write_bytes(gpx_bytes)
    assert _gdal_times(tmp_path / "t.gpx", "time") == want

    kml = ET.fromstring(c.get("/api/tracks/export?format=kml", headers=AUTH).content)
    whens = {w.text for w in kml.iter(f"{{{KML_NS}}}when")}
    assert whens == want
    assert {d.text for d in kml.iter(f"{{{KML_NS}}}value") if d.text in ("yes", "no")} == {"yes"}
    assert len(list(kml.iter(f"{{{GX_NS}}}coord"))) == len(want)

    (tmp_path / "t.gpkg").write_bytes(c.get("/api/tracks/export?format=gpkg", headers=AUTH).content)
    assert _gdal_times(tmp_path / "t.gpkg", "time_utc") == want

    geo = c.get("/api/tracks/export?format=geojson", headers=AUTH).json()
    props = geo["features"][0]["properties"]
    assert props["wall_clock"] is True and props["time"].startswith("times are UTC")


def test_markers_take_an_iso_time(real):
    c, _ = real
    r = c.post(
        "/api/markers",
        headers=AUTH,
        json={"time": "2026-12-01T15:32:05.5+01:00", "e_m": 10.0, "n_m": 20.0},
    )
    assert r.status_code == 201, r.text
    assert r.json()["t_s"] == T0_S + 125.5
    assert r.json()["time_utc"] == "2026-12-01T14:32:05.500Z"
    for body, words in (
        ({"time": "2026-12-01T15:32:05", "e_m": 1.0, "n_m": 2.0}, "no zone"),
        ({"e_m": 1.0, "n_m": 2.0}, "one of them"),
        ({"t_s": T0_S, "time": "2026-12-01T14:30:00Z", "e_m": 1.0, "n_m": 2.0}, "one of them"),
    ):
        r = c.post("/api/markers", headers=AUTH, json=body)
        assert r.status_code == 422 and words in r.json()["detail"], r.text
