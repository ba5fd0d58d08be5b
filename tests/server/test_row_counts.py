"""``Store.counts`` (kept by triggers) equals COUNT(*) after every kind of write."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.tracking.types import Detection
from demtrack.server.store import database as db


def _true_counts(store: db.Store) -> dict[str, int]:
    return {
        t: int(store._w.execute(f"SELECT COUNT(*) FROM {t}").fetchone()[0])  # noqa: S608
        for t in db.COUNTED_TABLES
    }


def _track(i: int, t: float) -> dict:
    return {
        "id": i,
        "cls": "human",
        "t_start": 0.0,
        "t_end": t,
        "e_min": 0.0,
        "n_min": 0.0,
        "e_max": 1.0,
        "n_max": 1.0,
        "sensors": ["cam1"],
        "live": True,
        "body": {"id": i, "cls": "human", "points": [{"t_s": t, "e_m": 0.0, "n_m": 0.0}]},
    }


def _activity(key: str, t: float) -> dict:
    return {
        "key": key,
        "kind": "loiter",
        "t_start_s": 0.0,
        "t_end_s": t,
        "track_ids": [1],
        "open": True,
    }


@pytest.mark.parametrize("seed", range(4))
def test_counts_follow_inserts_replacements_and_deletes(tmp_path, seed):
    rng = np.random.default_rng(seed)
    store = db.Store(tmp_path / "c.sqlite3")
    assert store.counts() == dict.fromkeys(db.COUNTED_TABLES, 0)
    det_ids: list[int] = []
    for step in range(40):
        op = rng.integers(0, 4)
        if op == 0 or not det_ids:
            n = int(rng.integers(1, 5))
            dets = [Detection(float(step), "cam1", (1.0, 1.0, 5.0, 9.0), "human")] * n
            store.insert_batch(dets, {"n_records": n, "accepted": n}, None)
            det_ids = [i for (i,) in store._w.execute("SELECT id FROM detections")]
        elif op == 1:
            # Fixes, some of detections that already have one (INSERT OR REPLACE).
            ids = rng.choice(det_ids, size=min(len(det_ids), 3), replace=False)
            fixes = [(int(i), 0.0, "cam1", "human", "ok", {"step": step}) for i in ids]
            events = [("fix", {"type": "fix", "k": k}) for k in range(len(fixes))]
            store.write_derived(fixes, [], events)
        elif op == 2:
            # Tracks upserted, or all replaced but a kept few.
            ids = [int(i) for i in rng.integers(1, 8, size=3)]
            if rng.random() < 0.3:
                keep = [ids[0]]
                store.write_derived(
                    [], [_track(ids[1], step)], [], replace_tracks=True, keep_track_ids=keep
                )
            else:
                store.write_derived([], [_track(i, step) for i in set(ids)], [])
        else:
            keys = [f"k{int(k)}" for k in rng.integers(0, 5, size=2)]
            store.write_derived([], [], [], activity=[_activity(k, step) for k in set(keys)])
        assert store.counts() == _true_counts(store), step
    store.close()
    # Reopened: the counts are in the file.
    again = db.Store(tmp_path / "c.sqlite3")
    assert again.counts() == _true_counts(again)
    again.close()


def test_a_version_4_file_gets_its_counts_when_migrated(tmp_path, monkeypatch):
    path = tmp_path / "old.sqlite3"
    with monkeypatch.context() as m:
        m.setattr(db, "MIGRATIONS", db.MIGRATIONS[:4])
        m.setattr(db, "SCHEMA_VERSION", 4)
        old = db.Store(path)
        dets = [Detection(1.0, "cam1", (1.0, 1.0, 5.0, 9.0), "human")] * 3
        old.insert_batch(dets, {"n_records": 3, "accepted": 3}, None)
        old.write_derived(
            [(1, 1.0, "cam1", "human", "ok", {})], [_track(5, 1.0)], [("fix", {"type": "fix"})]
        )
        assert old.schema_version() == 4
        old.close()
    store = db.Store(path)
    assert store.schema_version() == db.SCHEMA_VERSION
    want = {"batches": 1, "detections": 3, "fixes": 1, "tracks": 1, "events": 1, "activity": 0}
    assert store.counts() == want == _true_counts(store)
    store.write_derived([(1, 2.0, "cam1", "human", "ok", {})], [_track(5, 2.0)], [])
    assert store.counts() == want
    store.close()
