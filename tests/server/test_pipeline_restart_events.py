"""Events replay identically after a crash (issue 26, item 15).

A kill between two batches, or after a batch's commit and before its processing (the
start-up then processes it), must leave the same detected events (hand-off predictions,
tracks confirmed and ended, activity) as an uninterrupted run of the same batches. The
oracle is that uninterrupted run. ``test_e2e`` does the same with a real SIGKILL.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from server_helpers import stored_messages, time_batches, vehicle_run_pipeline

from demtrack.server.ingest.group_commit import Request, commit_group
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(900)
UNTIL_S = 60.0
PARAMS = LiveEventParams(window_s=15.0)


def _pipeline(site, path: Path) -> Pipeline:
    p = Pipeline(site, Store(path), "kalman", lambda _m: None, events=PARAMS)
    p.start()
    return p


def _events(store: Store) -> tuple[list[dict], list[tuple]]:
    """The activity table, and the stream's detected-event messages (not ``ingest``)."""
    activity = store.activity()
    stream = [
        (m["kind"], m["t_s"], m["text"], m.get("event"))
        for m in stored_messages(store)
        if m["type"] == "event" and m["kind"] != "ingest"
    ]
    return activity, stream


@pytest.fixture(scope="module")
def scenario(sample_site_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ref")
    site, p, records = vehicle_run_pipeline(sample_site_dir, tmp, UNTIL_S)
    p.store.close()
    batches = time_batches(records, 0.5)
    ref = _pipeline(site, tmp / "ref.sqlite3")
    for b in batches:
        ref.ingest(b)
    out = _events(ref.store), ref.store.tracks()
    ref.store.close()
    return site, batches, out


@pytest.mark.parametrize("where", [0.2, 0.45, 0.7, 0.9])
@pytest.mark.parametrize("how", ["between-batches", "after-commit"])
def test_events_after_a_crash_are_those_of_an_uninterrupted_run(scenario, tmp_path, where, how):
    site, batches, ((ref_activity, ref_stream), ref_tracks) = scenario
    kill = int(where * len(batches))
    path = tmp_path / "crashed.sqlite3"
    p = _pipeline(site, path)
    for b in batches[:kill]:
        p.ingest(b)
    if how == "after-commit":  # durable, never processed: the start-up processes it
        assert commit_group(p.store, [Request(batches[kill], None)], p._accept) is not None
        kill += 1
    p.store.close()  # the process dies here: nothing in memory survives
    again = _pipeline(site, path)
    for b in batches[kill:]:
        again.ingest(b)
    activity, stream = _events(again.store)
    assert ref_stream, "the scenario makes events"
    assert {k for k, *_ in ref_stream} >= {"handoff", "track_confirmed"}
    assert stream == ref_stream
    assert activity == ref_activity
    assert again.store.tracks() == ref_tracks
    again.store.close()
