"""The live tracker forgets long-ended tracks; SQLite and the API keep them all."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)

#: Loops of the clip, each this far after the previous one's start (s): longer than the
#: clip (18 s), the 4 s coast and the 30 s re-acquisition window together.
_N_LOOPS = 4
_PERIOD_S = 60.0


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def looped_batches(site):
    """The first 18 s of vehicle-run, looped, as per-camera per-frame batches."""
    clip = [d for d in make_scenario(site, "vehicle-run").detections if d.t_s < 18.0]
    frames: dict[tuple[float, str], list[dict]] = {}
    for k in range(_N_LOOPS):
        for d in clip:
            t = round(d.t_s + k * _PERIOD_S, 6)
            rec = {"t": t, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls}
            frames.setdefault((t, d.sensor), []).append(rec)
    return [frames[key] for key in sorted(frames)]


def _run(site, path: Path, batches, retain_s: float) -> tuple[Pipeline, list[tuple[int, int]]]:
    """Ingest ``batches``; also the tracker's (live, ended) record counts after each loop."""
    p = Pipeline(site, Store(path), "kalman", lambda _m: None, retain_ended_s=retain_s)
    p.start()
    held = []
    loop = 0
    for b in batches:
        if b[0]["t"] >= (loop + 1) * _PERIOD_S:
            held.append(p.tracker.n_held)
            loop += 1
        p.ingest(b)
    held.append(p.tracker.n_held)
    return p, held


def test_ended_tracks_are_dropped_from_memory_but_kept_in_the_store(site, looped_batches, tmp_path):
    keep_all, held_all = _run(site, tmp_path / "all.sqlite3", looped_batches, math.inf)
    bounded, held = _run(site, tmp_path / "bounded.sqlite3", looped_batches, 0.0)
    stored = keep_all.store.tracks()
    # each loop makes its own tracks (the gap is longer than the re-acquisition window)
    assert len(stored) >= _N_LOOPS
    ended_all = [e for _, e in held_all]
    ended = [e for _, e in held]
    # without the limit the ended tracks pile up, loop after loop
    assert ended_all[-1] >= len(stored) - max(ended_all[0], 1) and ended_all == sorted(ended_all)
    assert ended_all[-1] > ended_all[1]
    # with it, at most one loop's tracks are held (those inside the 30 s window)
    per_loop = max(ended_all[1] - ended_all[0], 1)
    assert max(ended) <= per_loop < ended_all[-1]
    # the store and the API's source are unchanged by forgetting
    assert bounded.store.tracks() == stored
    assert {t.id for t in bounded.tracker.tracks()} < {b["id"] for b in stored}
    # a restart replays the fixes, forgets the same tracks again, and keeps their rows
    bounded.store.close()
    again = Pipeline(site, Store(tmp_path / "bounded.sqlite3"), "kalman", lambda _m: None)
    again.retain_ended_s = 0.0
    again.start()
    assert again.store.tracks() == stored
    assert again.tracker.n_held[1] <= per_loop


def test_the_events_window_and_reacquisition_window_are_kept(site, looped_batches, tmp_path):
    from demtrack.server.live_events import LiveEventParams

    p = Pipeline(
        site,
        Store(tmp_path / "e.sqlite3"),
        "kalman",
        lambda _m: None,
        retain_ended_s=0.0,
        events=LiveEventParams(window_s=500.0),
    )
    assert p.keep_ended_s == 500.0
    p.start()
    for b in looped_batches:
        p.ingest(b)
    # 500 s of events window: nothing has ended long enough ago to go
    assert {t.id for t in p.tracker.tracks()} == {b["id"] for b in p.store.tracks()}
