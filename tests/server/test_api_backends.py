"""The API and the stream give the same bytes on SQLite and on PostgreSQL.

Oracle: the same posts (detections of two sensors in keyed batches, one resent, a marker
added, renamed and removed) to a console on a SQLite file and to one on a PostgreSQL
database; every answer of a representative set of reads (detections, tracks, one track,
exports, events, synopsis, markers, status) and every stream message after ``hello`` are
compared byte for byte. The same is then checked on real ``demtrack serve`` processes
(uvicorn), one per database.
"""

from __future__ import annotations

import json

import httpx2 as httpx
import pytest
from server_helpers import AUTH, TOKEN, make_app, start_server, walk
from starlette.testclient import TestClient

pytestmark = pytest.mark.timeout(300)


def feed() -> list[tuple[str, str, dict]]:
    """``(method, path, json)`` posts, in order."""
    recs: list[dict] = []
    for k in range(30):
        recs += walk(n=30)[k : k + 1]
        recs += walk(sensor="cam2", n=30, u0=300, v=600, cls="human")[k : k + 1]
    out = [
        ("POST", "/api/detections", {"detections": recs[i : i + 6], "batch_key": f"b{i}"})
        for i in range(0, len(recs), 6)
    ]
    out.insert(3, out[1])  # a resent batch: acknowledged again, stored once
    out.append(("POST", "/api/markers", {"e_m": 10.0, "n_m": 20.0, "name": "", "t_s": 3.0}))
    out.append(("PATCH", "/api/markers/1", {"name": "gate"}))
    out.append(("POST", "/api/markers", {"e_m": 11.0, "n_m": 21.0, "name": "b", "t_s": 4.0}))
    out.append(("DELETE", "/api/markers/2", {}))
    return out


READS = [
    "/api/detections?limit=10000",
    "/api/detections?sensor=cam2&t_from=1&t_to=4",
    "/api/tracks",
    "/api/tracks?cls=human",
    "/api/tracks/1",
    "/api/tracks/export?format=geojson",
    "/api/tracks/export?format=csv",
    "/api/tracks/export?format=gpx",
    "/api/events",
    "/api/synopsis?t_from=0&t_to=10",
    "/api/markers",
    "/api/status",
]


def _post_all(send) -> list[bytes]:
    out = []
    for method, path, body in feed():
        r = send(method, path, body)
        assert r.status_code in (200, 201, 204), (path, r.text)
        out.append(r.content)
    return out


def _read_all(get) -> list[bytes]:
    out = []
    for path in READS:
        r = get(path)
        assert r.status_code == 200, (path, r.text)
        out.append(r.content)
    return out


def _console(client: TestClient) -> tuple[list[bytes], list[bytes], list[str]]:
    def send(method, path, body):
        return client.request(method, path, headers=AUTH, json=body or None)

    acks = _post_all(send)
    reads = _read_all(lambda p: client.get(p, headers=AUTH))
    last = client.get("/api/status", headers=AUTH).json()["last_seq"]
    texts = []
    with client.websocket_connect(f"/ws?token={TOKEN}&since=0") as ws:
        assert json.loads(ws.receive_text())["type"] == "hello"
        while not texts or json.loads(texts[-1]).get("seq") != last:
            texts.append(ws.receive_text())
    return acks, reads, texts


def test_the_api_and_the_stream_answer_alike_on_both(sample_site_dir, tmp_path, postgres_url):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with TestClient(make_app(sample_site_dir, tmp_path / "a")) as c:
        lite = _console(c)
        assert c.app.state.console.store.kind == "sqlite"
    with TestClient(make_app(sample_site_dir, tmp_path / "b", database_url=postgres_url)) as c:
        pg = _console(c)
        assert c.app.state.console.store.kind == "postgres"
    for name, x, y in zip(("acks", "reads", "stream"), lite, pg, strict=True):
        assert len(x) == len(y), name
        for k, (a, b) in enumerate(zip(x, y, strict=True)):
            assert a == b, (name, k, READS[k] if name == "reads" else None)
    tracks = json.loads(pg[1][2])["tracks"]
    assert tracks and any(m["type"] == "track_update" for m in map(json.loads, pg[2]))


def _serve_run(site, tmp, *args: str) -> list[bytes]:
    proc, url = start_server(site, tmp / "c.sqlite3", *args, timeout_s=90)
    try:
        with httpx.Client(base_url=url, headers=AUTH, timeout=30) as c:
            acks = _post_all(lambda m, p, b: c.request(m, p, json=b or None))
            return acks + _read_all(c.get)
    finally:
        proc.kill()
        proc.wait(10)


def test_real_servers_answer_alike_on_both(sample_site_dir, tmp_path, postgres_url):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    lite = _serve_run(sample_site_dir, tmp_path / "a")
    pg = _serve_run(sample_site_dir, tmp_path / "b", "--database-url", postgres_url)
    assert len(lite) == len(pg)
    for k, (a, b) in enumerate(zip(lite, pg, strict=True)):
        assert a == b, k
