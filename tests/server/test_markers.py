"""``/api/markers``: stored, streamed as ``marker`` messages, exported, kept over a restart."""

from __future__ import annotations

import csv
import io
import json
from datetime import UTC, datetime

import mgrs
import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import rasterio
import shapely
from fastapi.testclient import TestClient
from pydantic import TypeAdapter
from server_helpers import AUTH, TOKEN, make_app

from demtrack.core.site.folder import load_site
from demtrack.server.messages import ServerMessage
from demtrack.server.site_info import geoid_grid_path
from demtrack.server.store.database import SCHEMA_VERSION
from demtrack.server.store.opening import open_store

pytestmark = pytest.mark.timeout(60)
MSG = TypeAdapter(ServerMessage)
T0 = 1_767_225_600.25  # 2026-01-01T00:00:00.250Z


def _recv_marker(ws):
    while True:
        m = ws.receive_json()
        MSG.validate_python(m)  # every message matches the exported schema's models
        if m["type"] == "marker":
            return m


def test_marker_is_stored_with_wgs84_mgrs_and_utc_and_streamed(client, sample_site_dir):
    frame = load_site(sample_site_dir).frame
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        ws.receive_json()  # hello
        r = client.post(
            "/api/markers",
            headers=AUTH,
            json={
                "t_s": T0,
                "e_m": 120.0,
                "n_m": -35.5,
                "u_m": 14.0,
                "note": "white van",
                "source": {"sensor": "cam1", "pixel": [10.5, 20.0], "rule": "first"},
            },
        )
        assert r.status_code == 201, r.text
        m = r.json()
        msg = _recv_marker(ws)
    assert msg["action"] == "add" and msg["marker"] == m and msg["id"] == m["id"]
    assert m["name"] == f"M{m['id']}" and m["note"] == "white van"
    lat, lon, h = frame.to_geodetic(120.0, -35.5, 14.0)  # the site frame, independently
    assert (m["lat_deg"], m["lon_deg"], m["h_m"]) == pytest.approx((lat, lon, h), abs=1e-9)
    assert m["time_utc"] == "2026-01-01T00:00:00.250Z"
    assert datetime.fromisoformat(m["time_utc"]) == datetime.fromtimestamp(T0, UTC)
    # MGRS: the mgrs package's own reference, and it reads back to the point within 1.5 m
    assert m["mgrs"].replace(" ", "") == mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
    lat2, lon2 = mgrs.MGRS().toLatLon(m["mgrs"].replace(" ", ""))
    e2, n2, _ = frame.to_enu(lat2, lon2, h)
    assert np.hypot(e2 - 120.0, n2 + 35.5) < 1.5
    assert client.get("/api/markers", headers=AUTH).json()["markers"] == [m]


def test_marker_from_wgs84_round_trips_and_ground_height_defaults_to_dem(client, sample_site_dir):
    site = load_site(sample_site_dir)
    lat, lon, h = site.frame.to_geodetic(50.0, 60.0, 10.0)
    m = client.post(
        "/api/markers", headers=AUTH, json={"t_s": T0, "lat_deg": lat, "lon_deg": lon, "h_m": h}
    ).json()
    assert (m["e_m"], m["n_m"], m["u_m"]) == pytest.approx((50.0, 60.0, 10.0), abs=1e-6)
    g = client.post("/api/markers", headers=AUTH, json={"t_s": T0, "e_m": 50.0, "n_m": 60.0})
    ground = client.get("/api/site/elevation?e=50&n=60", headers=AUTH).json()["u_m"]
    assert g.json()["u_m"] == pytest.approx(ground)


def test_marker_refusals_are_one_line(client):
    assert client.post("/api/markers", json={"t_s": T0, "e_m": 1, "n_m": 2}).status_code == 401
    both = client.post(
        "/api/markers",
        headers=AUTH,
        json={"t_s": T0, "e_m": 1, "n_m": 2, "lat_deg": 1, "lon_deg": 2},
    )
    assert both.status_code == 422 and "not both" in both.text
    none = client.post("/api/markers", headers=AUTH, json={"t_s": T0})
    assert none.status_code == 422
    for t in (1e300, -1e12):  # found by the schema fuzz: a 500 from the UTC conversion
        far = client.post("/api/markers", headers=AUTH, json={"t_s": t, "e_m": 1, "n_m": 2})
        assert far.status_code == 422, far.text
    assert client.delete("/api/markers/99", headers=AUTH).status_code == 404
    assert client.delete("/api/markers/1").status_code == 401


def test_delete_is_streamed_and_markers_survive_a_restart(sample_site_dir, tmp_path, store_kw):
    with TestClient(make_app(sample_site_dir, tmp_path, **store_kw)) as c:
        a = c.post(
            "/api/markers",
            headers=AUTH,
            json={"t_s": T0, "e_m": 1, "n_m": 2, "u_m": 3, "name": "gate"},
        ).json()
        b = c.post(
            "/api/markers", headers=AUTH, json={"t_s": T0 + 5, "e_m": 4, "n_m": 5, "u_m": 6}
        ).json()
        with c.websocket_connect(f"/ws?token={TOKEN}") as ws:
            ws.receive_json()
            assert c.delete(f"/api/markers/{a['id']}", headers=AUTH).status_code == 204
            gone = _recv_marker(ws)
        assert gone == {
            "type": "marker",
            "action": "delete",
            "id": a["id"],
            "marker": None,
            "seq": gone["seq"],
        }
        # a console resuming from before both sees the add and the delete, in order
        with c.websocket_connect(f"/ws?token={TOKEN}&since=0") as ws:
            ws.receive_json()
            seen = [_recv_marker(ws) for _ in range(3)]
        assert [(s["action"], s["id"]) for s in seen] == [
            ("add", a["id"]),
            ("add", b["id"]),
            ("delete", a["id"]),
        ]
    # the same database again
    with TestClient(make_app(sample_site_dir, tmp_path, **store_kw)) as c:
        assert c.get("/api/markers", headers=AUTH).json()["markers"] == [b]
        c3 = c.post("/api/markers", headers=AUTH, json={"t_s": T0, "e_m": 1, "n_m": 2, "u_m": 3})
        assert c3.json()["id"] > b["id"]  # a removed id is never reused
    store = open_store(store_kw.get("database_url") or tmp_path / "console.sqlite3")
    assert store.schema_version() == SCHEMA_VERSION
    store.close()


def test_export_geojson_lon_lat_h_and_csv_columns(client):
    m = client.post(
        "/api/markers",
        headers=AUTH,
        json={"t_s": T0, "e_m": 10, "n_m": 20, "u_m": 5, "name": "bridge"},
    ).json()
    g = client.get("/api/markers/export?format=geojson", headers=AUTH)
    assert g.headers["content-type"].startswith("application/geo+json")
    fc = json.loads(g.text)
    (f,) = fc["features"]
    assert f["geometry"]["coordinates"] == [m["lon_deg"], m["lat_deg"], m["h_m"]]
    assert f["properties"]["mgrs"] == m["mgrs"] and f["properties"]["time_utc"] == m["time_utc"]
    rows = list(
        csv.DictReader(io.StringIO(client.get("/api/markers/export?format=csv", headers=AUTH).text))
    )
    assert rows[0]["name"] == "bridge"
    assert float(rows[0]["longitude"]) == pytest.approx(m["lon_deg"])
    assert float(rows[0]["latitude"]) == pytest.approx(m["lat_deg"])
    assert client.get("/api/markers/export?format=kmz", headers=AUTH).status_code == 422


def _egm96_n(lat: float, lon: float) -> float:
    """EGM96 undulation read straight from the grid file, bilinear (independent of PROJ)."""
    grid = geoid_grid_path()
    with rasterio.open(grid) as ds:
        z = ds.read(1).astype(float)
        col, row = ~ds.transform @ (lon % 360.0 if ds.bounds.left >= -1 else lon, lat)
    c0, r0 = int(np.floor(col - 0.5)), int(np.floor(row - 0.5))
    fc, fr = col - 0.5 - c0, row - 0.5 - r0
    q = z[r0 : r0 + 2, c0 : c0 + 2]
    return float(
        q[0, 0] * (1 - fc) * (1 - fr)
        + q[0, 1] * fc * (1 - fr)
        + q[1, 0] * (1 - fc) * fr
        + q[1, 1] * fc * fr
    )


@pytest.mark.skipif(geoid_grid_path() is None, reason="needs proj-data's egm96_15.gtx")
@pytest.mark.parametrize("fmt", ["gpx", "kml"])
def test_export_gpx_kml_heights_above_the_geoid_read_by_gdal(client, tmp_path, fmt):
    m = client.post(
        "/api/markers",
        headers=AUTH,
        json={"t_s": T0, "e_m": 10, "n_m": 20, "u_m": 5, "name": "bridge", "note": "north pier"},
    ).json()
    r = client.get(f"/api/markers/export?format={fmt}", headers=AUTH)
    assert r.status_code == 200, r.text
    path = tmp_path / f"markers.{fmt}"
    path.write_bytes(r.content)
    layer = "waypoints" if fmt == "gpx" else None
    meta, _, geoms, fields = pyogrio.raw.read(path, layer=layer)
    cols = dict(zip(meta["fields"], fields, strict=True))
    (pt,) = shapely.from_wkb(geoms)
    assert pt.x == pytest.approx(m["lon_deg"], abs=1e-8)
    assert pt.y == pytest.approx(m["lat_deg"], abs=1e-8)
    want = m["h_m"] - _egm96_n(m["lat_deg"], m["lon_deg"])
    got = float(cols["ele"][0]) if fmt == "gpx" else pt.z
    assert got == pytest.approx(want, abs=0.01)  # metres above the geoid, not the ellipsoid
    assert abs(want - m["h_m"]) > 20  # Bushy Run: N is about -34 m
    assert "above sea level" in r.text and "EGM96" in r.text
    when = cols["time"][0] if fmt == "gpx" else cols["timestamp"][0]
    got_t = datetime.fromisoformat(str(when).replace("Z", "+00:00").replace("/", "-"))
    if got_t.tzinfo is None:
        got_t = got_t.replace(tzinfo=UTC)
    assert got_t == datetime.fromisoformat(m["time_utc"].replace("Z", "+00:00"))


def test_rename_and_note_are_stored_and_streamed(client):
    m = client.post("/api/markers", headers=AUTH, json={"t_s": T0, "e_m": 1, "n_m": 2, "u_m": 3})
    m = m.json()
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        ws.receive_json()
        r = client.patch(
            f"/api/markers/{m['id']}", headers=AUTH, json={"name": " gate ", "note": "x"}
        )
        assert r.status_code == 200, r.text
        msg = _recv_marker(ws)
    assert msg["action"] == "update" and msg["marker"] == r.json()
    assert r.json() == {**m, "name": "gate", "note": "x"}
    assert client.get("/api/markers", headers=AUTH).json()["markers"] == [r.json()]
    cleared = client.patch(f"/api/markers/{m['id']}", headers=AUTH, json={"name": ""}).json()
    assert cleared["name"] == f"M{m['id']}" and cleared["note"] == "x"
    assert client.patch("/api/markers/99", headers=AUTH, json={"name": "a"}).status_code == 404
    assert client.patch(f"/api/markers/{m['id']}", json={"name": "a"}).status_code == 401
