"""A real uvicorn process: ingest, SIGKILL mid-stream, restart; nothing acknowledged is lost
and the tracks and detected events are those an uninterrupted run makes."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx2 as httpx
import pytest
from server_helpers import AUTH, TOKEN, make_app, walk
from starlette.testclient import TestClient

pytestmark = pytest.mark.timeout(120)


def start(site: Path, db: Path, **extra_env: str) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "DEMTRACK_TOKEN": TOKEN, **extra_env}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "demtrack.cli",
            "serve",
            "--site",
            str(site),
            "--db",
            str(db),
            "--port",
            "0",
            "--no-warm-up",
            "--log-level",
            "info",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    deadline = time.monotonic() + 60
    assert proc.stdout is not None
    for line in proc.stdout:
        m = re.search(r"Uvicorn running on (http://[\d.]+:\d+)", line)
        if m:
            url = m.group(1)
            # keep draining the pipe so the server never blocks on a full one
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return proc, url
        if time.monotonic() > deadline:
            break
    proc.kill()
    raise AssertionError("server did not start")


def records() -> list[dict]:
    out = []
    for k in range(40):  # interleave two sensors in time order, 4 records per batch
        out += [r for r in walk(n=40)[k : k + 1]]
        out += [r for r in walk(sensor="cam2", n=40, u0=300, v=600, cls="human")[k : k + 1]]
    return out


def test_sigkill_mid_ingest_loses_no_acknowledged_detection(sample_site_dir, tmp_path):
    db = tmp_path / "console.sqlite3"
    recs = records()
    batches = [recs[i : i + 4] for i in range(0, len(recs), 4)]
    acked: list[dict] = []
    proc, url = start(sample_site_dir, db)
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
        proc, url = start(sample_site_dir, db)
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
            tracks = c.get("/api/tracks").json()["tracks"]
            seq = c.get("/api/health").json()["last_seq"]
            events = _events(c)
        assert len(stored) == len(recs)
        assert tracks
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
