"""The pipeline reads only recent ended tracks from the tracker, and streams the same.

A long live session ends thousands of tracks; the pipeline asks the tracker for the ended
tracks whose newest point is recent (its event window, or what it last sent of the tracks
that just ended) instead of rebuilding every track each time. Oracle: a twin pipeline
whose tracker ignores that bound (every ended track, as before) publishes the very same
messages and stores the same tracks.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest
from server_helpers import scenario_stream

from demtrack.core.site.folder import load_site
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def _run(site, path: Path, batches, *, reference: bool) -> tuple[list[dict], list, list]:
    msgs: list[dict] = []
    p = Pipeline(site, Store(path), "kalman", msgs.extend, events=LiveEventParams(window_s=15.0))
    p.start()
    bounds: list[float | None] = []
    full = p.tracker.tracks

    def tracks(*, include_ended: bool = True, ended_after_s: float | None = None):
        bounds.append(ended_after_s)
        return full(include_ended=include_ended, ended_after_s=None if reference else ended_after_s)

    p.tracker.tracks = tracks  # type: ignore[method-assign]
    for batch in batches:
        p.ingest(batch)
    return msgs, p.store.tracks(), bounds


def test_recent_ended_tracks_stream_like_all_of_them(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    frames = scenario_stream(
        site, ["passing-vehicles", "pedestrians"], 0.0, rate_hz=5.0, duration_s=100.0
    )
    batches = [
        [r for f in group for r in f.records]
        for _, group in itertools.groupby(frames, key=lambda f: int(f.t_s))
    ]
    fast, fast_tracks, bounds = _run(site, tmp_path / "fast.sqlite3", batches, reference=False)
    ref, ref_tracks, _ = _run(site, tmp_path / "ref.sqlite3", batches, reference=True)
    assert fast == ref
    assert fast_tracks == ref_tracks
    # Tracks ended (the passing cars loop every ~42 s) and the bound was a real time.
    ended = {
        m["track"]["id"] for m in fast if m["type"] == "track_update" and not m["track"]["live"]
    }
    assert len(ended) >= 2
    assert sum(1 for b in bounds if b is not None and math.isfinite(b) and b > 0) > 50
