from __future__ import annotations

import asyncio
import json

import pytest
from pydantic import TypeAdapter
from server_helpers import AUTH, TOKEN, walk

from demtrack.core.io.times import format_utc
from demtrack.server.hub import OVERFLOW, Hub
from demtrack.server.messages import ServerMessage

pytestmark = pytest.mark.timeout(60)
MSG = TypeAdapter(ServerMessage)


def recv(ws):
    msg = ws.receive_json()
    MSG.validate_python(msg)  # every message the server sends matches the schema
    return msg


def recv_until(ws, seq):
    out = []
    while True:
        m = recv(ws)
        out.append(m)
        if m.get("seq") == seq:
            return out


def test_live_messages_have_consecutive_seqs_and_resume_gets_the_missed(client):
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        hello = recv(ws)
        store_id = client.app.state.console.store.store_id
        assert hello == {
            "type": "hello",
            "seq": None,
            "last_seq": 0,
            "since": None,
            "store_id": store_id,
            "start_over": False,
        }
        ack = client.post("/api/detections", headers=AUTH, json={"detections": walk(n=10)}).json()
        last = client.get("/api/status", headers=AUTH).json()["last_seq"]
        live = recv_until(ws, last)
    assert [m["seq"] for m in live] == list(range(1, last + 1))
    fixes = [m for m in live if m["type"] == "fix"]
    assert [m["fix"]["detection_id"] for m in fixes] == ack["detection_ids"]
    assert all(m["fix"]["hits"] for m in fixes)
    assert {m["type"] for m in live} >= {"fix", "track_update", "sensor_status", "event"}
    # more while the client is away, then resume from what it saw
    client.post("/api/detections", headers=AUTH, json={"detections": walk(n=5, t0=10)})
    last2 = client.get("/api/status", headers=AUTH).json()["last_seq"]
    with client.websocket_connect(f"/ws?token={TOKEN}&since={last}") as ws:
        assert recv(ws)["since"] == last
        missed = recv_until(ws, last2)
        assert [m["seq"] for m in missed] == list(range(last + 1, last2 + 1))
        # in-connection resume from the start replays everything again, in order
        ws.send_json({"type": "resume", "since": 0})
        again = recv_until(ws, last2)
        assert [m["seq"] for m in again] == list(range(1, last2 + 1))
        assert again[: len(live)] == live


def test_track_updates_rebuild_the_stored_tracks(client):
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        recv(ws)
        for k in range(3):
            client.post(
                "/api/detections",
                headers=AUTH,
                json={"detections": walk(n=30)[10 * k : 10 * k + 10]},
            )
        last = client.get("/api/status", headers=AUTH).json()["last_seq"]
        msgs = recv_until(ws, last)
    rebuilt: dict[int, list] = {}
    for m in msgs:
        if m["type"] == "track_update":
            t = m["track"]
            pts = rebuilt.setdefault(t["id"], [])
            assert t["first_index"] <= len(pts)
            del pts[t["first_index"] :]
            pts.extend(t["points"])
            assert len(pts) == t["n_points"]
    stored = client.get("/api/tracks", headers=AUTH).json()["tracks"]
    # the HTTP answer adds each point's ISO time (time_utc) beside the t_s streamed
    for t in stored:
        for p in t["points"]:
            assert p.pop("time_utc") == format_utc(p["t_s"])
    assert stored and {t["id"]: t["points"] for t in stored} == rebuilt


def test_malformed_messages_get_an_error_and_the_connection_stays(client_factory):
    c = client_factory(max_ws_message_bytes=200)
    with c.websocket_connect(f"/ws?token={TOKEN}") as ws:
        recv(ws)
        for bad in (
            "not json",
            "{}",
            '{"type": "dance"}',
            '{"type": "resume", "since": -1}',
            json.dumps({"type": "ping", "nonce": "x" * 500}),
        ):
            ws.send_text(bad)
            m = recv(ws)
            assert m["type"] == "error" and m["message"], bad
        ws.send_bytes(b"\x00\x01")
        assert recv(ws)["type"] == "error"
        ws.send_json({"type": "ping", "nonce": 7})
        assert recv(ws) == {"type": "pong", "seq": None, "nonce": 7}


def test_bad_since_is_refused(client):
    from starlette.websockets import WebSocketDisconnect

    for q in ("since=-1", "since=x"):
        # told in an error message first (issue 26: not a silent close), then closed
        with client.websocket_connect(f"/ws?token={TOKEN}&{q}") as ws:
            assert recv(ws)["type"] == "error"
            with pytest.raises(WebSocketDisconnect) as err:
                ws.receive_json()
        assert err.value.code == 1008


def test_hub_drops_a_slow_client_without_blocking_the_others():
    async def run():
        hub = Hub(queue_size=3)
        hub.bind(asyncio.get_running_loop())
        slow, fast = hub.register(), hub.register()
        for k in range(1, 7):
            hub.publish([{"type": "event", "seq": k}])
            got = fast.queue.get_nowait()  # the fast client keeps up
            assert got[0] == k
        assert slow.overflowed and slow.queue.get_nowait() == OVERFLOW
        assert not fast.overflowed and hub.n_dropped == 1
        hub.publish_threadsafe([{"type": "event", "seq": 7}])
        await asyncio.sleep(0)
        assert fast.queue.get_nowait()[0] == 7 and hub.last_seq == 7

    asyncio.run(run())


def test_slow_client_is_closed_with_1013_and_can_resume(client_factory):
    from starlette.websockets import WebSocketDisconnect

    c = client_factory(ws_queue_size=2)
    with c.websocket_connect(f"/ws?token={TOKEN}") as ws:
        recv(ws)
        # one batch makes many more than 2 messages at once: the queue overflows
        c.post("/api/detections", headers=AUTH, json={"detections": walk(n=10)})
        with pytest.raises(WebSocketDisconnect) as err:
            while True:
                ws.receive_json()
        assert err.value.code == 1013
    last = c.get("/api/status", headers=AUTH).json()["last_seq"]
    with c.websocket_connect(f"/ws?token={TOKEN}&since=0") as ws:
        recv(ws)
        assert [m["seq"] for m in recv_until(ws, last)] == list(range(1, last + 1))
