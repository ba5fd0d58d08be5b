"""The demo replay stamps real UTC times (issue 27): from ``replay_start_s``, never before
what is stored. Oracle: the scenario's own first detection time plus the start."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app

from demtrack.server.settings import Settings

pytestmark = pytest.mark.timeout(600)
START = "2026-12-01T15:30:00+01:00"
START_S = 1796135400.0  # 2026-12-01T14:30:00Z


def _play(app, n_frames=20):
    replay = app.state.replay
    deadline = time.monotonic() + 120
    while replay.n_frames < n_frames and time.monotonic() < deadline:
        time.sleep(0.05)
    assert replay.stop() and replay.n_frames >= n_frames


def test_replay_starts_at_the_given_utc_time_and_after_what_is_stored(
    sample_site_dir, tmp_path, store_kw
):
    kw = {"replay": ["passing-vehicles"], "replay_speed": 500.0, "replay_start_s": START}
    kw.update(store_kw)
    app = make_app(sample_site_dir, tmp_path, **kw)
    with TestClient(app) as client:
        _play(app)
        first = client.get("/api/detections?after_id=0&limit=10000", headers=AUTH).json()
    assert min(d["t"] for d in first) >= START_S
    assert min(d["t"] for d in first) < START_S + 5.0  # the scenario's first frames
    assert first[0]["time_utc"].startswith("2026-12-01T14:30:")
    newest = max(d["t"] for d in first)
    # a restart with the same start continues after the stored times, not at the start
    app = make_app(sample_site_dir, tmp_path, **kw)
    with TestClient(app) as client:
        _play(app)
        body = client.get("/api/detections?after_id=0&limit=10000", headers=AUTH).json()
    later = [d["t"] for d in body if d["t"] > newest]
    assert later and min(later) >= newest + 5.0


def test_replay_start_settings(tmp_path):
    def made(**kw):
        return Settings(site=tmp_path, **kw).replay_start_s

    assert abs(made(replay_start_s="now") - time.time()) < 2.0
    assert made(replay_start_s=START) == START_S
    assert made(replay_start_s=12.5) == 12.5
    assert made() is None
    with pytest.raises(ValueError, match="no zone"):
        made(replay_start_s="2026-12-01T14:30:00")
