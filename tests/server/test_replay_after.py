"""``app.state.replay_after``: the replay sends nothing until the hook returns."""

from __future__ import annotations

import threading
import time

from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app


def test_the_replay_waits_for_its_hook_then_plays(sample_site_dir, tmp_path, store_kw):
    app = make_app(
        sample_site_dir,
        tmp_path,
        replay=["passing-vehicles"],
        replay_speed=500.0,
        replay_loop=False,
        **store_kw,
    )
    called = threading.Event()
    release = threading.Event()

    def after() -> None:  # as demtrack demo's wait for the tracker's warm-up child
        called.set()
        release.wait(60)

    app.state.replay_after = after
    with TestClient(app) as client:
        replay = app.state.replay
        assert called.wait(60), "the replay never called its hook"
        time.sleep(0.5)  # at 500x, frames would have been sent by now
        assert replay.n_batches == 0
        assert client.get("/api/status", headers=AUTH).json()["counts"]["detections"] == 0
        release.set()
        deadline = time.monotonic() + 120
        while replay.running and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not replay.running and replay.error is None
        assert replay.n_records > 0 and replay.n_accepted == replay.n_records
