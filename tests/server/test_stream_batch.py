"""``/ws?batch=1``: several stream messages per frame, each exactly once and in order."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest
from pydantic import TypeAdapter
from server_helpers import AUTH, TOKEN, walk

from demtrack.server.hub import OVERFLOW, Hub, batch_text, pack, take
from demtrack.server.messages import BATCH_MAX_MESSAGES, ServerMessage

pytestmark = pytest.mark.timeout(60)
MSG = TypeAdapter(ServerMessage)


def texts(n: int, width: int = 0) -> list[str]:
    """``n`` encoded stream messages (``seq`` 1..n), each padded with ``width`` characters."""
    return [
        json.dumps({"type": "event", "seq": k, "kind": "ingest", "t_s": None, "text": "x" * width})
        for k in range(1, n + 1)
    ]


def frames_until(ws: Any, seq: int) -> list[dict[str, Any]]:
    """Frames (parsed, schema-checked) up to the one that carries stream message ``seq``."""
    out = []
    while True:
        frame = json.loads(ws.receive_text())
        MSG.validate_python(frame)  # every frame the server sends matches the schema
        out.append(frame)
        inner = frame["messages"] if frame["type"] == "batch" else [frame]
        if any(m.get("seq") == seq for m in inner):
            return out


def unpack(frames: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The stream messages of ``frames`` in the order a client applies them."""
    out = []
    for f in frames:
        out.extend(f["messages"] if f["type"] == "batch" else [f])
    return [m for m in out if m.get("seq") is not None]


def post_and_last(c: Any, detections: list[dict[str, Any]]) -> int:
    c.post("/api/detections", headers=AUTH, json={"detections": detections})
    return int(c.get("/api/status", headers=AUTH).json()["last_seq"])


# ------------------------------------------------------------------------ pack / take
@pytest.mark.parametrize("n", [1, 2, 5, 7, 300, 600])
@pytest.mark.parametrize("max_messages", [1, 3, BATCH_MAX_MESSAGES])
def test_pack_keeps_every_message_once_in_order_within_the_cap(n, max_messages):
    src = texts(n)
    frames = pack(src, max_messages, 10**9)
    got = unpack([json.loads(f) for f in frames])
    assert got == [json.loads(t) for t in src]
    for f in frames:
        parsed = json.loads(f)
        MSG.validate_python(parsed)
        if parsed["type"] == "batch":
            assert 2 <= len(parsed["messages"]) <= max_messages
        else:
            assert f in src  # a lone message goes as it was encoded
    assert len(frames) == -(-n // max_messages)  # as few frames as the cap allows


def test_pack_stops_a_frame_once_it_holds_max_chars():
    src = texts(19, width=100)
    size = len(src[0])
    frames = pack(src, BATCH_MAX_MESSAGES, 3 * size)
    assert [len(json.loads(f)["messages"]) for f in frames[:-1]] == [3] * 6
    assert json.loads(frames[-1]) == json.loads(src[-1])  # the 19th alone
    # one message longer than the cap still goes, alone
    assert pack(src[:2], BATCH_MAX_MESSAGES, 1) == src[:2]


def test_batch_text_is_the_envelope_of_the_encoded_messages():
    src = texts(3)
    assert json.loads(batch_text(src)) == {
        "type": "batch",
        "seq": None,
        "messages": [json.loads(t) for t in src],
    }


def test_take_drains_up_to_the_cap_and_stops_at_overflow():
    async def run():
        hub = Hub(queue_size=100)
        hub.bind(asyncio.get_running_loop())
        client = hub.register(batch=True)
        hub.publish([{"type": "event", "seq": k} for k in range(1, 8)])
        first = await client.queue.get()
        items, over = take(client, first, 3, 10**9)
        assert [s for s, _ in items] == [1, 2, 3] and not over
        items, over = take(client, await client.queue.get(), 10, 10**9)
        assert [s for s, _ in items] == [4, 5, 6, 7] and not over and client.queue.empty()
        client.queue.put_nowait((8, "{}"))
        client.queue.put_nowait(OVERFLOW)
        items, over = take(client, await client.queue.get(), 10, 10**9)
        assert [s for s, _ in items] == [8] and over

    asyncio.run(run())


# ------------------------------------------------------------------------------- /ws
def test_batched_client_gets_every_message_once_in_order_across_frames_and_resume(
    client_factory,
):
    c = client_factory()
    hub = c.app.state.console.hub
    hub.batch_max_messages = 3  # small, so that batches end inside every publish
    with c.websocket_connect(f"/ws?token={TOKEN}&batch=1") as ws:
        hello = json.loads(ws.receive_text())
        assert hello["type"] == "hello" and hello["last_seq"] == 0
        last = post_and_last(c, walk(n=10))
        live_frames = frames_until(ws, last)
        # a ping between batches is answered on its own, not inside a batch
        ws.send_json({"type": "ping", "nonce": 1})
        assert json.loads(ws.receive_text()) == {"type": "pong", "seq": None, "nonce": 1}
    live = unpack(live_frames)
    assert [m["seq"] for m in live] == list(range(1, last + 1))
    sizes = [len(f["messages"]) for f in live_frames if f["type"] == "batch"]
    assert sizes and max(sizes) == 3  # a publish of many messages went in frames of 3
    assert all(2 <= n <= 3 for n in sizes)
    # the same messages as a client that did not opt in is sent, one per frame
    with c.websocket_connect(f"/ws?token={TOKEN}&since=0") as ws:
        assert json.loads(ws.receive_text())["since"] == 0
        single = frames_until(ws, last)
    assert single == live and all(f["type"] != "batch" for f in single)
    # more while away; resume from the middle of a batch gets exactly the rest
    mid = live_frames[0]["messages"][1]["seq"] if live_frames[0]["type"] == "batch" else 1
    last2 = post_and_last(c, walk(n=5, t0=10))
    with c.websocket_connect(f"/ws?token={TOKEN}&since={mid}&batch=1") as ws:
        assert json.loads(ws.receive_text())["since"] == mid
        missed_frames = frames_until(ws, last2)
        assert any(f["type"] == "batch" for f in missed_frames)  # the replay batches too
        missed = unpack(missed_frames)
        assert [m["seq"] for m in missed] == list(range(mid + 1, last2 + 1))
        assert missed[: last - mid] == live[mid:]
        # in-connection resume from the start: everything again, in order, batched
        ws.send_json({"type": "resume", "since": 0})
        again_frames = frames_until(ws, last2)
        assert [m["seq"] for m in unpack(again_frames)] == list(range(1, last2 + 1))
        assert all(len(f["messages"]) <= 3 for f in again_frames if f["type"] == "batch")


def test_without_the_flag_every_frame_is_one_message(client):
    for q in ("", "&batch=0"):
        with client.websocket_connect(f"/ws?token={TOKEN}{q}") as ws:
            json.loads(ws.receive_text())
            before = int(client.get("/api/status", headers=AUTH).json()["last_seq"])
            last = post_and_last(client, walk(n=8, t0=20 * len(q)))
            frames = frames_until(ws, last)
        assert all(f["type"] != "batch" for f in frames)
        assert [f["seq"] for f in frames] == list(range(before + 1, last + 1))


def test_the_character_cap_splits_frames(client_factory):
    c = client_factory()
    c.app.state.console.hub.batch_max_chars = 1  # every message is over the cap: alone
    last = post_and_last(c, walk(n=6))
    with c.websocket_connect(f"/ws?token={TOKEN}&since=0&batch=1") as ws:
        json.loads(ws.receive_text())
        frames = frames_until(ws, last)
    assert all(f["type"] != "batch" for f in frames)
    assert [f["seq"] for f in frames] == list(range(1, last + 1))


def test_bad_batch_flag_is_refused(client):
    from starlette.websockets import WebSocketDisconnect

    # told in an error message first (issue 26: not a silent close), then closed
    with client.websocket_connect(f"/ws?token={TOKEN}&batch=yes") as ws:
        msg = json.loads(ws.receive_text())
        assert msg == {"type": "error", "seq": None, "message": "batch must be 0 or 1"}
        with pytest.raises(WebSocketDisconnect) as err:
            ws.receive_text()
    assert err.value.code == 1008


def test_slow_batched_client_is_closed_with_1013_and_resumes_batched(client_factory):
    from starlette.websockets import WebSocketDisconnect

    c = client_factory(ws_queue_size=2)
    with c.websocket_connect(f"/ws?token={TOKEN}&batch=1") as ws:
        json.loads(ws.receive_text())
        # one publish of many more than 2 messages overflows the queue before it drains
        c.post("/api/detections", headers=AUTH, json={"detections": walk(n=10)})
        with pytest.raises(WebSocketDisconnect) as err:
            while True:
                ws.receive_text()
        assert err.value.code == 1013
    last = int(c.get("/api/status", headers=AUTH).json()["last_seq"])
    assert c.get("/api/status", headers=AUTH).json()["counts"]["ws_dropped"] == 1
    with c.websocket_connect(f"/ws?token={TOKEN}&since=0&batch=1") as ws:
        json.loads(ws.receive_text())
        assert [m["seq"] for m in unpack(frames_until(ws, last))] == list(range(1, last + 1))
