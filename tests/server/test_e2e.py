"""A real uvicorn process: ingest, SIGKILL mid-stream, restart; nothing acknowledged is lost
and the tracks and detected events are those an uninterrupted run makes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import httpx2 as httpx
import pytest
from server_helpers import AUTH, make_app, start_server, walk
from starlette.testclient import TestClient

pytestmark = pytest.mark.timeout(120)


def start(site: Path, db: Path, **extra_env: str) -> tuple[subprocess.Popen, str]:
    return start_server(site, db, timeout_s=60, **extra_env)


def records() -> list[dict]:
    out = []
    for k in range(40):  # interleave two sensors in time order, 4 records per batch
        out += [r for r in walk(n=40)[k : k + 1]]
        out += [r for r in walk(sensor="cam2", n=40, u0=300, v=600, cls="human")[k : k + 1]]
    return out


def _wait_until_tracked(database_url: str, n: int, timeout_s: float = 60.0) -> None:
    """Wait until ``n`` fixes are stored: on PostgreSQL the restarted server tracks only
    once it holds the site's lease, when the killed one's has expired (its TTL)."""
    import psycopg

    deadline = time.monotonic() + timeout_s
    while True:
        with psycopg.connect(database_url) as conn:
            (k,) = conn.execute("SELECT count(*) FROM fixes").fetchone()
        if k >= n or time.monotonic() > deadline:
            return
        time.sleep(0.1)


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_sigkill_mid_ingest_loses_no_acknowledged_detection(
    backend, sample_site_dir, tmp_path, request
):
    """On either database (PostgreSQL: ``DEMTRACK_DATABASE_URL``); the reference runs
    are SQLite's, so on PostgreSQL the tracks and events are also compared across them."""
    db = tmp_path / "console.sqlite3"
    env = {}
    if backend == "postgres":
        env["DEMTRACK_DATABASE_URL"] = request.getfixturevalue("postgres_url")
    recs = records()
    batches = [recs[i : i + 4] for i in range(0, len(recs), 4)]
    acked: list[dict] = []
    proc, url = start(sample_site_dir, db, **env)
    stop = threading.Event()

    def feed() -> None:
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            for k, batch in enumerate(batches):
                if stop.is_set():
                    return
                try:
                    r = c.post("/api/detections", json={"detections": batch, "batch_key": f"b{k}"})
                except httpx.HTTPError:
                    return
                if r.status_code == 200:
                    acked.append(r.json())

    try:
        t = threading.Thread(target=feed)
        t.start()
        while len(acked) < 6 and t.is_alive():
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGKILL)  # mid-stream: the feeder is still posting
        proc.wait(10)
        t.join(20)
        n_acked = len(acked)
        assert 6 <= n_acked < len(batches), "the kill should land mid-stream"
        proc, url = start(sample_site_dir, db, **env)
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            stored = c.get("/api/detections", params={"limit": 10000}).json()
            ids = {d["id"] for d in stored}
            for ack in acked:
                assert set(ack["detection_ids"]) <= ids
            got = {(d["t"], d["sensor"], tuple(d["bbox"])) for d in stored}
            sent = [(r["t"], r["sensor"], tuple(r["bbox"])) for b in batches[:n_acked] for r in b]
            assert set(sent) <= got
            # the rest of the feed goes on after the restart (resending is harmless)
            for k, batch in enumerate(batches):
                r = c.post("/api/detections", json={"detections": batch, "batch_key": f"b{k}"})
                assert r.status_code == 200
            stored = c.get("/api/detections", params={"limit": 10000}).json()
            if backend == "postgres":  # tracked by the lease holder, once it takes over
                _wait_until_tracked(env["DEMTRACK_DATABASE_URL"], len(recs))
            tracks = c.get("/api/tracks").json()["tracks"]
            seq = c.get("/api/health").json()["last_seq"]
            events = _events(c)
        assert len(stored) == len(recs)
        assert tracks
        assert backend == "sqlite" or not db.exists()  # the store really was PostgreSQL
    finally:
        proc.kill()
        proc.wait(10)
    assert seq > 0
    # an uninterrupted run over the same detections makes the same tracks
    (tmp_path / "ref").mkdir()
    with TestClient(make_app(sample_site_dir, tmp_path / "ref")) as ref:
        by_t = [
            {
                "t": d["t"],
                "sensor": d["sensor"],
                "bbox": d["bbox"],
                "class": d["class"],
                "score": d["score"],
                "local_id": d["local_id"],
            }
            for d in stored
        ]
        assert ref.post("/api/detections", headers=AUTH, json={"detections": by_t}).json()[
            "accepted"
        ] == len(recs)
        assert ref.get("/api/tracks", headers=AUTH).json()["tracks"] == tracks
    # ... and, posted in the same batches without a kill, the same events (hand-off
    # predictions, tracks confirmed and ended): the events replay identically too
    (tmp_path / "ref-batches").mkdir()
    with TestClient(make_app(sample_site_dir, tmp_path / "ref-batches")) as ref:
        for k, batch in enumerate(batches):
            r = ref.post(
                "/api/detections", headers=AUTH, json={"detections": batch, "batch_key": f"b{k}"}
            )
            assert r.status_code == 200
        ref_events = _events(ref, headers=AUTH)
        assert ref.get("/api/tracks", headers=AUTH).json()["tracks"] == tracks
    assert {e["kind"] for e in ref_events["detected"]} >= {"track_confirmed"}
    assert events == ref_events


def _events(c, **kw) -> dict[str, list]:
    """The stored events, and the hand-off predictions, without their row ids."""

    def rows(**params) -> list:
        got = c.get("/api/events", params={"limit": 10000, **params}, **kw).json()["events"]
        return [{k: v for k, v in e.items() if k != "id"} for e in got]

    return {"detected": rows(), "handoff": rows(kind="handoff")}


@pytest.mark.parametrize("setting", [None, "true"])
def test_websocket_compression_is_offered_only_when_set(sample_site_dir, tmp_path, setting):
    """permessage-deflate costs one compression per client per message: off by default."""
    from websockets.sync.client import connect

    extra = {} if setting is None else {"DEMTRACK_WS_COMPRESSION": setting}
    proc, url = start(sample_site_dir, tmp_path / "c.sqlite3", **extra)
    try:
        ws_url = url.replace("http://", "ws://") + "/ws"
        with connect(ws_url, additional_headers=AUTH, compression="deflate") as ws:
            offered = ws.response.headers.get("Sec-WebSocket-Extensions") or ""
            assert ("permessage-deflate" in offered) == (setting is not None)
            assert "type" in json.loads(ws.recv(timeout=10))
    finally:
        proc.kill()
        proc.wait(10)


def _active_site(src: Path, dst: Path) -> Path:
    """A copy of the sample site whose ``cam1`` is an active (PTZ) head."""
    import shutil

    shutil.copytree(src, dst)
    doc = json.loads((dst / "site.json").read_text("utf-8"))
    for s in doc["sensors"]:
        if s["id"] == "cam1":
            s["active"] = True
    (dst / "site.json").write_text(json.dumps(doc), "utf-8")
    return dst


def _pose_feed(pan0: float, tilt0: float) -> list[tuple[str, dict]]:
    """``(path, body)`` posts in order: cam1's poses ahead of the detections they cover."""
    recs = records()
    batches = [recs[i : i + 4] for i in range(0, len(recs), 4)]
    poses = [
        {"t": round(k * 0.1, 6), "pan_deg": pan0 + 0.05 * k, "tilt_deg": tilt0 - 0.01 * k}
        for k in range(85)
    ]
    out, sent = [], 0
    for k, batch in enumerate(batches):
        upto = min(len(poses), int(max(r["t"] for r in batch) / 0.1) + 3)
        if upto > sent:
            out.append(
                ("/api/sensors/cam1/poses", {"poses": poses[sent:upto], "batch_key": f"p{k}"})
            )
            sent = upto
        out.append(("/api/detections", {"detections": batch, "batch_key": f"b{k}"}))
    return out


def _fix_rows(db: Path) -> list[tuple]:
    import sqlite3

    with sqlite3.connect(db) as conn:
        return conn.execute(
            "SELECT detection_id, status, body FROM fixes ORDER BY detection_id"
        ).fetchall()


def test_sigkill_with_pose_telemetry_restarts_to_the_same_poses_fixes_tracks(
    sample_site_dir, tmp_path
):
    """An active sensor's poses and detections, the server SIGKILLed mid-run and restarted:
    poses, fixes and tracks identical to an uninterrupted run of the same posts."""
    from demtrack.core.site.folder import load_site

    site_dir = _active_site(sample_site_dir, tmp_path / "site")
    cam = load_site(site_dir).sensors["cam1"]
    posts = _pose_feed(cam.pan_deg, cam.tilt_deg)
    db = tmp_path / "console.sqlite3"
    acked: list[int] = []
    # the poses are the test's own: no simulated head reports cam1's
    proc, url = start(site_dir, db, DEMTRACK_HEADS="off")

    def feed() -> None:
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            for k, (path, body) in enumerate(posts):
                try:
                    r = c.post(path, json=body)
                except httpx.HTTPError:
                    return
                if r.status_code == 200:
                    acked.append(k)

    try:
        t = threading.Thread(target=feed)
        t.start()
        while len(acked) < 12 and t.is_alive():
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGKILL)  # mid-stream: poses and detections in flight
        proc.wait(10)
        t.join(20)
        assert 12 <= len(acked) < len(posts), "the kill should land mid-stream"
        proc, url = start(site_dir, db, DEMTRACK_HEADS="off")
        with httpx.Client(base_url=url, headers=AUTH, timeout=10) as c:
            for path, body in posts:  # the feed again from the start: resending is harmless
                assert c.post(path, json=body).status_code == 200
            poses = c.get("/api/sensors/cam1/poses").json()["poses"]
            tracks = c.get("/api/tracks").json()["tracks"]
            status = c.get("/api/status").json()["counts"]
            sensor = c.get("/api/sensors/cam1").json()
    finally:
        proc.kill()
        proc.wait(10)
    sent = [p for path, body in posts if "poses" in body for p in body["poses"]]
    assert [p["t_s"] for p in poses] == [p["t"] for p in sent]
    assert tracks and sensor["active"] and sensor["pose"]["t_s"] == sent[-1]["t"]
    assert status["pose_waiting"] == 0
    fixes = _fix_rows(db)
    assert sum(1 for _, s, _ in fixes if s == "fix") > 60
    (tmp_path / "ref").mkdir()
    with TestClient(make_app(site_dir, tmp_path / "ref", heads="off")) as ref:
        for path, body in posts:
            assert ref.post(path, headers=AUTH, json=body).status_code == 200
        assert ref.get("/api/sensors/cam1/poses", headers=AUTH).json()["poses"] == poses
        assert ref.get("/api/tracks", headers=AUTH).json()["tracks"] == tracks
    assert _fix_rows(tmp_path / "ref" / "console.sqlite3") == fixes
