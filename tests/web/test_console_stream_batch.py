"""The console takes batched stream frames (``/ws?batch=1``) and applies every message once."""

from __future__ import annotations

import json
from typing import Any

import pytest
from web_helpers import AUTH, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(600)

_STREAM_JS = """() => {
  const s = window.demtrack.stream;
  return {lastSeq: s.lastSeq, received: s.nReceived, frames: s.nFrames, gaps: s.nGaps,
          tracks: window.demtrack.store.tracks.size};
}"""


def _caught_up(page: Any, seq: int) -> dict[str, Any]:
    page.wait_for_function(f"window.demtrack.stream.lastSeq === {seq}", timeout=120_000)
    return dict(page.evaluate(_STREAM_JS))


def test_page_applies_batched_frames_once_each_live_and_after_resume(
    page, server_factory, scenario_records
):
    srv = server_factory("batch")
    frames: list[str] = []

    def watch(ws: Any) -> None:
        ws.on("framereceived", lambda payload: frames.append(payload))

    page.on("websocket", watch)
    open_console(page, srv)
    assert page.record.websockets and all("batch=1" in u for u in page.record.websockets)
    with srv.client() as c:
        post_until(c, scenario_records, -1.0, 6.0)
        seq = c.get("/api/health").json()["last_seq"]
        live = _caught_up(page, seq)
        # The frame events reach Playwright after the page counted them: wait for all of them.
        wait_until(lambda: len(frames) >= live["frames"], 60.0, 0.05, page=page)
        # Every stored message reached the page once (it opened on an empty database),
        # counted as messages, not frames; some frames carried several.
        assert live["received"] == seq and live["gaps"] == 0
        parsed = [json.loads(f) for f in frames]
        batches = [f for f in parsed if f["type"] == "batch"]
        assert batches and live["frames"] == len(parsed) < seq
        inner = [m for f in parsed for m in (f["messages"] if f["type"] == "batch" else [f])]
        assert [m["seq"] for m in inner if m.get("seq") is not None] == list(range(1, seq + 1))
        # Away while more arrives: the resume (?since=N&batch=1) replays it in batches.
        page.evaluate("() => { const s = window.demtrack.stream; s.closed = true; s.ws.close(); }")
        page.wait_for_function("window.demtrack.stream.ws === null", timeout=30_000)
        post_until(c, scenario_records, 6.0, 12.0)
        seq2 = c.get("/api/health").json()["last_seq"]
        n_frames = len(frames)
        page.evaluate("() => { const s = window.demtrack.stream; s.closed = false; s.connect(); }")
        after = _caught_up(page, seq2)
        n_tracks = len(c.get("/api/tracks", headers=AUTH).json()["tracks"])
    assert len(page.record.websockets) == 2 and f"since={seq}" in page.record.websockets[1]
    assert after["received"] == seq2 and after["gaps"] == 0
    replayed = [json.loads(f) for f in frames[n_frames:]]
    assert any(f["type"] == "batch" for f in replayed)
    assert after["tracks"] == n_tracks > 0
    assert page.record.errors == []
