"""The stream's identity: a ``since`` of another store, or beyond the newest message, never
silences a client; a ``since`` out of range gets a clear error (issue 26, item 1)."""

from __future__ import annotations

import pytest
from pydantic import TypeAdapter
from server_helpers import AUTH, TOKEN, walk
from starlette.websockets import WebSocketDisconnect

from demtrack.server.messages import ServerMessage
from demtrack.server.store.opening import open_store

pytestmark = pytest.mark.timeout(120)
MSG = TypeAdapter(ServerMessage)
HUGE = 10**40


def recv(ws):
    msg = ws.receive_json()
    MSG.validate_python(msg)  # every message the server sends matches the schema
    return msg


def last_seq(client) -> int:
    return client.get("/api/status", headers=AUTH).json()["last_seq"]


def post(client, **kw) -> None:
    r = client.post("/api/detections", headers=AUTH, json={"detections": walk(**kw)})
    assert r.status_code == 200, r.text


def first_stream_message(ws) -> dict:
    while True:
        m = recv(ws)
        if m.get("seq") is not None:
            return m


def test_store_id_is_made_with_the_database_and_kept(tmp_path, store_backend, request):
    if store_backend == "sqlite":
        targets = [tmp_path / "a.sqlite3", tmp_path / "b.sqlite3"]
    else:  # two copies of the tests' migrated template: each still gets its own id
        cluster = request.getfixturevalue("postgres_cluster")
        targets = [cluster.create_store_database() for _ in range(2)]
    a, b = (open_store(t) for t in targets)
    ida, idb = a.store_id, b.store_id
    a.close()
    b.close()
    assert len(ida) >= 16 and ida != idb
    again = open_store(targets[0])
    assert again.store_id == ida
    again.close()


def test_hello_names_the_store(client):
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        hello = recv(ws)
    assert hello["store_id"] == client.app.state.console.store.store_id
    assert hello["start_over"] is False


@pytest.mark.parametrize("beyond", [False, True], ids=["other-store", "beyond-newest"])
def test_a_since_that_cannot_resume_starts_over_and_stays_live(client, beyond):
    post(client, n=10)
    last = last_seq(client)
    store_id = client.app.state.console.store.store_id
    # a page of another store held since=last+500 (the old file went further)
    since = last + 500
    query = f"since={since}" + ("" if beyond else "&store=0123456789abcdef")
    with client.websocket_connect(f"/ws?token={TOKEN}&{query}") as ws:
        hello = recv(ws)
        assert hello["start_over"] is True and hello["last_seq"] == last
        assert hello["store_id"] == store_id
        post(client, n=5, t0=10)
        m = first_stream_message(ws)  # before the fix: nothing until seq passed since
        assert m["seq"] == last + 1


def test_a_since_of_this_store_resumes(client):
    post(client, n=10)
    store_id = client.app.state.console.store.store_id
    with client.websocket_connect(f"/ws?token={TOKEN}&since=3&store={store_id}") as ws:
        hello = recv(ws)
        assert hello["start_over"] is False and hello["since"] == 3
        assert first_stream_message(ws)["seq"] == 4


@pytest.mark.parametrize("since", [str(HUGE), str(2**63), "-1", "x", "1" * 5000])
def test_a_since_out_of_range_is_told_not_silently_closed(client, since):
    with client.websocket_connect(f"/ws?token={TOKEN}&since={since}") as ws:
        err = recv(ws)
        assert err["type"] == "error"
        assert err["message"].startswith("since must be an integer from 0 to 9223372036854775807")
        assert "\n" not in err["message"] and len(err["message"]) < 200
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
    assert closed.value.code == 1008


def test_a_resume_out_of_range_is_told_and_the_connection_stays(client):
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        recv(ws)
        ws.send_text(f'{{"type": "resume", "since": {HUGE}}}')
        err = recv(ws)
        assert err["type"] == "error" and "since" in err["message"]
        ws.send_json({"type": "ping", "nonce": 7})
        assert recv(ws) == {"type": "pong", "seq": None, "nonce": 7}


def test_a_resume_beyond_the_newest_starts_over_and_stays_live(client):
    post(client, n=10)
    last = last_seq(client)
    with client.websocket_connect(f"/ws?token={TOKEN}") as ws:
        recv(ws)
        ws.send_json({"type": "resume", "since": last + 1000})
        hello = recv(ws)
        assert hello["type"] == "hello" and hello["start_over"] is True
        post(client, n=5, t0=10)
        assert first_stream_message(ws)["seq"] == last + 1
