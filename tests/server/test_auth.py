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


# ------------------------------------------------ the token first, the logs, liveness
def _asgi_post(app, path: str, headers: list[tuple[bytes, bytes]], body: bytes):
    """Call ``app`` with one POST; the messages sent and how often the body was asked for."""
    import anyio

    asked: list[int] = []
    sent: list[dict] = []

    async def receive() -> dict:
        asked.append(1)
        return {"type": "http.request", "body": body, "more_body": False}

    async def send(message: dict) -> None:
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "root_path": "",
        "query_string": b"",
        "headers": [(b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()), *headers],
        "client": ("127.0.0.1", 5000),
        "server": ("testserver", 80),
        "state": {},
    }  # fmt: skip
    anyio.run(app, scope, receive, send)
    return sent, len(asked)


def test_the_token_is_checked_before_the_body_is_read(client):
    body = b'{"detections": [' + b'{"t": 1, "sensor": "cam1"},' * 1000 + b"{}]}"
    sent, asked = _asgi_post(client.app, "/api/detections", [], body)
    assert sent[0]["status"] == 401 and asked == 0
    assert b"operator token required" in sent[1]["body"]
    auth = [(b"authorization", f"Bearer {TOKEN}".encode())]
    sent, asked = _asgi_post(client.app, "/api/geolocate", auth, b'{"sensor": "nope"}')
    assert asked >= 1 and sent[0]["status"] == 422  # with the token the body is read


def test_too_large_names_the_limit(client_factory):
    c = client_factory(max_body_bytes=2000)
    r = c.post("/api/detections", json={"detections": walk(n=100)}, headers=AUTH)
    assert r.status_code == 413
    detail = r.json()["detail"]
    assert "limit of 2000 bytes" in detail and "\n" not in detail
    r = c.post("/api/detections", json={"detections": walk(n=100)})  # no token: 401 first
    assert r.status_code == 401


def test_the_redactor_hides_the_token_in_uvicorn_records():
    import logging

    from demtrack.server.security import TokenRedactor, redact

    assert redact("/ws?token=abc&since=3") == "/ws?token=***&since=3"
    assert redact("/api/site?x=1&token=abc") == "/api/site?x=1&token=***"
    record = logging.LogRecord(
        "uvicorn.error", logging.INFO, __file__, 1, '%s - "WebSocket %s" [accepted]',
        ("127.0.0.1:5", "/ws?token=secret-value"), None,
    )  # fmt: skip
    TokenRedactor().filter(record)
    assert "secret-value" not in record.getMessage() and "token=***" in record.getMessage()


def test_a_real_server_never_logs_the_token(sample_site_dir, tmp_path):
    import re
    import subprocess
    import sys

    import httpx2 as httpx
    from websockets.sync.client import connect

    env = {**os.environ, "DEMTRACK_TOKEN": TOKEN}
    proc = subprocess.Popen(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(sample_site_dir),
         "--db", str(tmp_path / "c.sqlite3"), "--port", "0", "--no-warm-up",
         "--log-level", "info"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
    )  # fmt: skip
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            m = re.search(r"Uvicorn running on http://([\d.]+:\d+)", line)
            if m:
                address = m.group(1)
                break
        else:
            raise AssertionError("server did not start:\n" + "".join(lines))
        with connect(f"ws://{address}/ws?token={TOKEN}") as ws:
            assert '"hello"' in str(ws.recv(timeout=30))
        assert httpx.get(f"http://{address}/api/site?token={TOKEN}").status_code == 200
        assert httpx.get(f"http://{address}/api/tracks?token={TOKEN}&cls=x").status_code < 500
    finally:
        proc.terminate()
        rest, _ = proc.communicate(timeout=30)
    log = "".join(lines) + rest
    assert "WebSocket /ws?token=***" in log and "/api/site?token=***" in log, log
    assert TOKEN not in log, log


def test_health_answers_while_every_worker_thread_is_busy(client, monkeypatch):
    import threading

    import httpx2 as httpx
    import uvicorn

    from demtrack.server import listing

    release, started = threading.Event(), threading.Semaphore(0)
    real = listing.list_detections

    def slow(*args, **kwargs):
        started.release()
        release.wait(60)
        return real(*args, **kwargs)

    monkeypatch.setattr(listing, "list_detections", slow)
    app = client.app  # started (lifespan run) by the fixture; served on loopback too
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0,
                                           log_level="warning", lifespan="off"))  # fmt: skip
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        threading.Event().wait(0.05)
    url = f"http://127.0.0.1:{server.servers[0].sockets[0].getsockname()[1]}"
    readers = [
        threading.Thread(target=httpx.get, args=(f"{url}/api/detections",),
                         kwargs={"headers": AUTH, "timeout": 90})
        for _ in range(48)
    ]  # fmt: skip
    try:
        for t in readers:
            t.start()
        for _ in range(40):  # anyio's default: 40 worker threads, all now held by reads
            assert started.acquire(timeout=60)
        r = httpx.get(f"{url}/api/health", timeout=10)
        assert r.status_code == 200 and r.json()["status"] == "ok"
        assert not release.is_set()  # answered while every read still waited
    finally:
        release.set()
        for t in readers:
            t.join(90)
        server.should_exit = True
        thread.join(30)
