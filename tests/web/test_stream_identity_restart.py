"""An open console survives its server's restart on a fresh database (issue 26, item 1).

The real server is SIGKILLed and started again on the same port with a new, empty file;
the page reconnects with its old ``?since=N`` (N from the first store) and must start
over and receive the new store's stream within seconds - before, the server skipped every
message until the new file's sequence passed N, while the pill said "connected".
"""

from __future__ import annotations

import signal

import pytest
from web_helpers import Server, free_port, open_console, post_until, wait_until

pytestmark = pytest.mark.timeout(400)


def _state(page):
    return page.evaluate(
        "() => ({last: window.demtrack.stream.lastSeq, store: window.demtrack.stream.storeId,"
        " resets: window.demtrack.stream.nResets, n: window.demtrack.stream.nReceived,"
        " tracks: [...window.demtrack.store.tracks.keys()].sort((a, b) => a - b),"
        " conn: document.querySelector('#conn').dataset.state})"
    )


def test_page_starts_over_and_streams_after_a_restart_on_a_fresh_database(
    page, sample_site_dir, tmp_path, scenario_records
):
    first = Server(sample_site_dir, tmp_path / "first.sqlite3", free_port()).start()
    try:
        open_console(page, first)
        with first.client() as c:
            post_until(c, scenario_records, -1.0, 40.0, step_s=5.0)
            old_last = c.get("/api/status").json()["last_seq"]
        assert old_last > 100
        before = wait_until(lambda: (s := _state(page))["last"] == old_last and s, page=page)
        assert before, _state(page)
        old_store = before["store"]
        assert isinstance(old_store, str) and old_store
    finally:
        first.stop(signal.SIGKILL)  # the server dies; the page keeps its ?since=old_last
    second = Server(sample_site_dir, tmp_path / "second.sqlite3", first.port).start()
    try:
        with second.client() as c:
            post_until(c, scenario_records, -1.0, 10.0, step_s=5.0)
            new_last = c.get("/api/status").json()["last_seq"]
            new_tracks = sorted(t["id"] for t in c.get("/api/tracks").json()["tracks"])
        assert 0 < new_last < old_last  # the new store's seqs stay below the page's since
        assert new_tracks
        # within seconds: the page is on the new store, has every message and its tracks
        after = wait_until(
            lambda: (s := _state(page))["last"] == new_last and s["conn"] == "live" and s,
            timeout_s=20.0,
            page=page,
        )
        assert after, _state(page)
        assert after["store"] != old_store
        assert after["resets"] == 1
        assert set(new_tracks) <= set(after["tracks"])
        # and it stays live: more detections on the new store reach it too
        with second.client() as c:
            post_until(c, scenario_records, 10.0, 20.0, step_s=5.0)
            newer = c.get("/api/status").json()["last_seq"]
        assert wait_until(lambda: _state(page)["last"] == newer, timeout_s=20.0, page=page)
    finally:
        second.stop()
