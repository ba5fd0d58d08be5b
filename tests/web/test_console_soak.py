"""A short soak of the console: a busy replay at 10x streamed into a real browser.

The server replays the three sample-site scenarios, two staggered copies each (about ten
tracks at once), at 10x for 90 s of scenario time; the page is open from before the first
frame, so everything it holds came over the stream. Its store's caps are lowered first so
that they are exercised within the run. Oracles, once the replay has ended and the page
has caught up with the server's newest ``seq``: no sequence gap; the page holds exactly
the API's tracks, each with the API's newest points up to the per-track cap; each
camera's fixes are the newest stored detections of that camera, up to the cap; every
collection is within its cap; the track count shown is the API's. No timing assertions.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from web_helpers import TOKEN, open_console

from demtrack.bench.console_soak import page_state, replay_server

pytestmark = pytest.mark.timeout(900)

DURATION_S = 90.0
#: The replay's first time (UTC): scenario time 0 is stamped there.
START = "2026-12-01T14:30:00Z"
T0 = datetime(2026, 12, 1, 14, 30, tzinfo=UTC).timestamp()
#: Lowered caps (the defaults are far beyond what 90 s of replay reaches).
CAPS = {"pointsPerTrack": 150, "fixesPerSensor": 60, "events": 5, "detToTrack": 800}


@pytest.fixture
def soak_server(sample_site_dir: Path, tmp_path: Path):
    srv = replay_server(
        sample_site_dir,
        tmp_path / "soak.sqlite3",
        TOKEN,
        speed=10.0,
        copies=2,
        rate_hz=10.0,
        duration_s=DURATION_S,
        start=START,
    )
    srv.start()
    try:
        yield srv
    finally:
        srv.stop()


def _stored_stream(server: Any, last_seq: int) -> list[dict[str, Any]]:
    """Every stored stream message up to ``last_seq``, read on a WebSocket of our own."""
    from websockets.sync.client import connect

    url = f"ws://127.0.0.1:{server.port}/ws?since=0&token={TOKEN}"
    out: list[dict[str, Any]] = []
    with connect(url, max_size=None, open_timeout=30) as ws:
        while not out or out[-1]["seq"] < last_seq:
            msg = json.loads(ws.recv(timeout=60))
            if msg.get("seq") is not None:
                out.append(msg)
    return out


def _settled(page: Any, api: Any, timeout_s: float = 600.0) -> int:
    """Wait until the replay has ended and the page has the server's newest seq.

    Ended: a detection of the scenario's last second is stored and no message came for
    5 s (a batch can take seconds on a busy machine, so quiet alone is not enough).
    """
    deadline = page.evaluate("performance.now()") + 1000 * timeout_s
    last = -1
    end = {"t_from": T0 + DURATION_S - 1.0, "limit": 1}
    while page.evaluate("performance.now()") < deadline:
        seq = api.get("/api/health").json()["last_seq"]
        if seq == last and api.get("/api/detections", params=end).json():
            if page_state(page)["lastSeq"] == seq:
                return seq
        last = seq
        page.wait_for_timeout(5000)
    raise AssertionError("the replay did not end or the page did not catch up")


def test_busy_replay_streams_without_gaps_and_stays_within_caps(soak_server, page):
    # soak_server first: it outlives the page, whose screenshot shows the live console
    open_console(page, soak_server)
    page.evaluate(
        """async (caps) => {
            const { LIMITS } = await import("/console/store.mjs");
            Object.assign(LIMITS, caps);
        }""",
        CAPS,
    )
    with soak_server.client() as api:
        seq = _settled(page, api)
        tracks = api.get("/api/tracks").json()["tracks"]
    stored = _stored_stream(soak_server, seq)
    st = page_state(page)
    assert st["limits"] == {**st["limits"], **CAPS}  # the page runs with the lowered caps
    assert st["lastSeq"] == seq and st["gaps"] == 0
    assert [m["seq"] for m in stored] == list(range(1, seq + 1))
    # The replay reached its scenario end, with several tracks and cut by the caps.
    fix_msgs = [m["fix"] for m in stored if m["type"] == "fix"]
    assert T0 + DURATION_S - 1.0 < max(f["t_s"] for f in fix_msgs) < T0 + DURATION_S
    assert len(tracks) >= 8
    assert max(len(t["points"]) for t in tracks) > CAPS["pointsPerTrack"]
    # The page's tracks are the API's; each holds the API's newest points up to the cap.
    held = page.evaluate(
        """() => [...window.demtrack.store.tracks.values()].map((t) => ({
            id: t.id, base: t.base, t: t.points.map((p) => p.t_s), e: t.points.map((p) => p.e_m)
        }))"""
    )
    assert sorted(h["id"] for h in held) == sorted(t["id"] for t in tracks)
    by_id = {t["id"]: t for t in tracks}
    for h in held:
        want = by_id[h["id"]]["points"][-CAPS["pointsPerTrack"] :]
        assert h["t"] == [p["t_s"] for p in want], f"track {h['id']}"
        assert h["e"] == [p["e_m"] for p in want], f"track {h['id']}"
        assert h["base"] == len(by_id[h["id"]]["points"]) - len(want)
    # Each camera's fixes: the newest fixes of that camera on the stream, up to the cap.
    fixes = page.evaluate(
        """() => Object.fromEntries([...window.demtrack.store.fixes.entries()]
            .map(([s, l]) => [s, l.map((f) => f.detection_id)]))"""
    )
    sensors = sorted({f["sensor"] for f in fix_msgs})
    assert sorted(fixes) == sensors
    for s in sensors:
        ids = [f["detection_id"] for f in fix_msgs if f["sensor"] == s]
        assert len(ids) > CAPS["fixesPerSensor"]
        assert fixes[s] == ids[-CAPS["fixesPerSensor"] :], s
    assert st["events"] <= CAPS["events"] and st["detToTrack"] <= CAPS["detToTrack"]
    assert st["detToTrack"] == CAPS["detToTrack"]  # more detections than that were tracked
    # What the page shows: the API's number of tracks, in the counts and the list header.
    n = len(tracks)
    assert st["tracks"] == n
    shown = f"({n})" if n <= 100 else f"(100 of {n})"
    # The lists are redrawn at most every 0.4 s, later on a loaded machine: wait for the redraw.
    page.wait_for_function(
        """([n, shown]) => document.querySelector('#counts').innerText.startsWith(`${n} tracks`)
             && document.querySelector('#n-tracks').innerText === shown""",
        arg=[n, shown],
        timeout=60_000,
    )
    assert page.locator("#counts").inner_text().startswith(f"{n} tracks")
    assert page.locator("#n-tracks").inner_text() == shown
    assert page.record.errors == [], page.record.errors
