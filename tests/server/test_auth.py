from __future__ import annotations

import os
import stat

import pytest
from server_helpers import AUTH, TOKEN, make_app, walk
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

READS = [
    "/api/site",
    "/api/site/orthophoto.png",
    "/api/site/relief.png",
    "/api/site/roads.geojson",
    "/api/sensors",
    "/api/sensors/cam1",
    "/api/sensors/cam1/image",
    "/api/detections",
    "/api/tracks",
    "/api/status",
]


def test_every_read_needs_the_token_by_default(ro_client):
    for path in READS:
        r = ro_client.get(path)
        assert r.status_code == 401, path
        assert "token" in r.json()["detail"]
        assert ro_client.get(path, headers={"Authorization": "Bearer wrong"}).status_code == 401
    assert ro_client.get("/api/health").status_code == 200
    r = ro_client.post("/api/geolocate", json={"sensor": "cam1", "u": 1, "v": 1})
    assert r.status_code == 401


def test_token_ways_header_query(ro_client):
    assert ro_client.get("/api/site", headers={"X-Demtrack-Token": TOKEN}).status_code == 200
    assert ro_client.get(f"/api/site?token={TOKEN}").status_code == 200


def test_open_reads_opens_reads_but_not_writes(client_factory):
    c = client_factory(open_reads=True)
    assert c.get("/api/site").status_code == 200
    r = c.post("/api/detections", json={"detections": walk(n=2)})
    assert r.status_code == 401
    with pytest.raises(WebSocketDisconnect) as err, c.websocket_connect("/ws"):
        pass
    assert err.value.code == 1008


def test_websocket_needs_the_token(ro_client):
    for url in ("/ws", "/ws?token=wrong"):
        with pytest.raises(WebSocketDisconnect) as err, ro_client.websocket_connect(url):
            pass
        assert err.value.code == 1008


def test_cors_closed_by_default_and_open_when_configured(client_factory):
    origin = {"Origin": "http://evil.example", **AUTH}
    c = client_factory()
    r = c.get("/api/site", headers=origin)
    assert "access-control-allow-origin" not in r.headers
    r = c.options(
        "/api/site",
        headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "GET"},
    )
    assert "access-control-allow-origin" not in r.headers
    c2 = client_factory(cors_origins=["http://console.example"])
    r = c2.get("/api/site", headers={"Origin": "http://console.example", **AUTH})
    assert r.headers["access-control-allow-origin"] == "http://console.example"
    r = c2.get("/api/site", headers=origin)
    assert "access-control-allow-origin" not in r.headers


def test_body_size_limit(client_factory):
    c = client_factory(max_body_bytes=2000)
    r = c.post("/api/detections", json={"detections": walk(n=100)}, headers=AUTH)
    assert r.status_code == 413
    r = c.post("/api/detections", json={"detections": walk(n=2)}, headers=AUTH)
    assert r.status_code == 200


def test_batch_record_limit(client_factory):
    c = client_factory(max_batch=5)
    r = c.post("/api/detections", json={"detections": walk(n=6)}, headers=AUTH)
    assert r.status_code == 413 and "limit is 5" in r.json()["detail"]


def test_generated_token_is_saved_private_and_reused(sample_site_dir, tmp_path):
    app = make_app(sample_site_dir, tmp_path, token=None)
    assert app.state.token_generated and len(app.state.token) >= 32
    path = app.state.token_file
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    again = make_app(sample_site_dir, tmp_path, token=None)
    assert not again.state.token_generated and again.state.token == app.state.token
    with TestClient(again) as c:
        assert (
            c.get("/api/site", headers={"Authorization": f"Bearer {app.state.token}"}).status_code
            == 200
        )


def test_settings_come_from_the_environment(monkeypatch, sample_site_dir, tmp_path):
    from demtrack.server.app import create_app

    monkeypatch.setenv("DEMTRACK_SITE", str(sample_site_dir))
    monkeypatch.setenv("DEMTRACK_DB_PATH", str(tmp_path / "x.sqlite3"))
    monkeypatch.setenv("DEMTRACK_TOKEN", "from-env")
    monkeypatch.setenv("DEMTRACK_OPEN_READS", "true")
    app = create_app()
    assert app.state.token == "from-env" and app.state.settings.open_reads


def test_bad_settings_are_one_line_errors(sample_site_dir, tmp_path):
    from demtrack.core.errors import DemtrackError

    with pytest.raises(DemtrackError, match="tracker method"):
        make_app(sample_site_dir, tmp_path, tracker_method="nope")
    with pytest.raises(DemtrackError, match="not a site folder"):
        make_app(tmp_path, tmp_path)
