"""A disk that fills between a batch's commit and its processing (issue 26, item 15).

The batch is acknowledged (its detections committed); its derived write (fixes, tracks,
activity, stream events) is refused by the full disk. Those rows used to be made only at
the next restart. Now they are held and written once space returns, with no restart and
no new batch (the retry timer), and the store ends as an uninterrupted run of the same
batches leaves it: the oracle is that run. The full disk is SQLite's own ``SQLITE_FULL``
(``PRAGMA max_page_count`` capped at the file's size), as in ``test_store_integrity``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest
from server_helpers import stored_messages, time_batches, vehicle_run_pipeline

from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.live_events import LiveEventParams
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)
UNTIL_S = 40.0
PARAMS = LiveEventParams(window_s=15.0)
NO_LIMIT = 1073741823


def _pipeline(site, path: Path, published: list | None = None) -> Pipeline:
    sink = (lambda m: published.extend(m)) if published is not None else (lambda _m: None)
    p = Pipeline(site, Store(path), "kalman", sink, events=PARAMS)
    p.start()
    return p


def _state(store: Store) -> tuple[list, list, list, list]:
    """Fixes, tracks, activity and the stream's event log (less ``ingest`` counts)."""
    fixes = store.fixes(0, 10**6)
    stream = [
        {k: v for k, v in m.items() if k != "seq"}
        for m in stored_messages(store)
        if not (m["type"] == "event" and m.get("kind") == "ingest")
    ]
    return fixes, store.tracks(), store.activity(), stream


def _unprocessed(store: Store) -> int:
    return len(store.detections(0, 10**6, unprocessed=True))


@pytest.fixture(scope="module")
def scenario(sample_site_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ref")
    site, p, records = vehicle_run_pipeline(sample_site_dir, tmp, UNTIL_S)
    p.store.close()
    batches = time_batches(records, 2.0)
    ref = _pipeline(site, tmp / "ref.sqlite3")
    for b in batches:
        ref.ingest(b)
    out = _state(ref.store)
    ref.close()
    ref.store.close()
    return site, batches, out


def _fill_before_next_derived_write(store: Store) -> None:
    """Cap the file at its size just before the next derived write (once)."""
    real = store.write_derived

    def fill_then_write(*a: Any, **kw: Any) -> Any:
        store.write_derived = real  # type: ignore[method-assign]
        pages = store._w.execute("PRAGMA page_count").fetchone()[0]
        store._w.execute(f"PRAGMA max_page_count = {pages}")
        return real(*a, **kw)

    store.write_derived = fill_then_write  # type: ignore[method-assign]


@pytest.mark.parametrize("where", [0.3, 0.7])
def test_a_batch_acknowledged_before_the_disk_filled_is_written_when_space_returns(
    scenario, tmp_path, where
):
    site, batches, ref = scenario
    k = int(where * len(batches))
    published: list = []
    p = _pipeline(site, tmp_path / "full.sqlite3", published)
    try:
        for b in batches[:k]:
            p.ingest(b)
        _fill_before_next_derived_write(p.store)
        n_sent = len(published)
        ack = p.ingest(batches[k])
        assert ack["accepted"] == len(batches[k])  # acknowledged: durable
        assert _unprocessed(p.store) == len(batches[k]), "the derived write was refused"
        assert len(published) == n_sent, "nothing is sent before it is stored"
        time.sleep(1.0)  # still full: the retries are refused, nothing lost
        assert _unprocessed(p.store) == len(batches[k])
        p.store._w.execute(f"PRAGMA max_page_count = {NO_LIMIT}")  # space returns
        deadline = time.monotonic() + 30.0
        while _unprocessed(p.store) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _unprocessed(p.store) == 0, "written without a restart or a new batch"
        assert len(published) > n_sent
        for b in batches[k + 1 :]:
            p.ingest(b)
        fixes, tracks, activity, stream = _state(p.store)
        ref_fixes, ref_tracks, ref_activity, ref_stream = ref
        assert fixes == ref_fixes
        assert tracks == ref_tracks
        assert activity == ref_activity
        assert stream == ref_stream
        seqs = [m["seq"] for m in published]
        assert seqs == sorted(seqs), "published in order"
    finally:
        p.close()
        p.store.close()


def test_a_refused_write_holds_the_later_ones_behind_it(scenario, tmp_path):
    """Batches processed while the disk is full are written after the held one, in order."""
    site, batches, ref = scenario
    k = len(batches) // 2
    p = _pipeline(site, tmp_path / "full.sqlite3")
    p.writes._delay = p.writes.max_retry_s = 3600.0  # no timer: the next batch retries
    try:
        for b in batches[:k]:
            p.ingest(b)
        _fill_before_next_derived_write(p.store)
        p.ingest(batches[k])
        assert _unprocessed(p.store) == len(batches[k])
        # space returns: the next batch's write stores the held one first, then its own
        p.store._w.execute(f"PRAGMA max_page_count = {NO_LIMIT}")
        for b in batches[k + 1 :]:
            p.ingest(b)
        assert _unprocessed(p.store) == 0
        assert _state(p.store) == ref
    finally:
        p.close()
        p.store.close()
