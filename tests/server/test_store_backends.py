"""The store's behaviour on both databases: SQLite (the file) and PostgreSQL + PostGIS.

Each test runs on both (the ``store`` fixture); the strongest oracle is the twin run at
the end: one scripted workload (batches with keys and poses, fixes, whole and partial
track writes, a table replaced, activity, events, markers) on a SQLite store and on a
PostgreSQL store, every read compared after every step.
"""

from __future__ import annotations

import pytest

from demtrack.core.tracking.types import Detection
from demtrack.server.store.codec import dumps_json
from demtrack.server.store.markers import add_marker, delete_marker, list_markers, update_marker
from demtrack.server.store.opening import open_store
from demtrack.server.store.queries import TrackTail

pytestmark = pytest.mark.timeout(300)


@pytest.fixture(params=["sqlite", "postgres"])
def store(request, tmp_path):
    target = tmp_path / "s.sqlite3" if request.param == "sqlite" else None
    s = open_store(target or request.getfixturevalue("postgres_url"))
    yield s
    s.close()


def det(t: float, sensor: str = "cam1", cls: str = "human", score: float | None = 0.9):
    return Detection(t, sensor, (10.0 + t, 10.0, 20.0 + t, 40.0), cls, score, f"{sensor}-{t}")


def report(n: int) -> dict:
    return {"n_records": n, "accepted": n}


def track_row(tid: int, points: list[tuple[float, float]], t0: float = 0.0, **kw) -> dict:
    pts = [{"t_s": t0 + k, "e_m": e, "n_m": n} for k, (e, n) in enumerate(points)]
    es, ns = [p[0] for p in points], [p[1] for p in points]
    row = {
        "id": tid,
        "cls": kw.get("cls", "human"),
        "t_start": t0,
        "t_end": t0 + len(points) - 1,
        "e_min": min(es),
        "n_min": min(ns),
        "e_max": max(es),
        "n_max": max(ns),
        "sensors": ["cam1"],
        "live": kw.get("live", True),
        "body": {"id": tid, "cls": kw.get("cls", "human"), "points": pts},
    }
    return row


def tail_row(tid: int, whole: list[tuple[float, float]], start: int) -> dict:
    row = track_row(tid, whole)
    pts = row["body"].pop("points")
    row["points_from"] = start
    row["point_texts"] = [dumps_json(p) for p in pts[start:]]
    return row


def test_kind_and_schema(store):
    assert store.kind in ("sqlite", "postgres")
    assert store.schema_version() == 7
    assert store.counts() == dict.fromkeys(
        ["batches", "detections", "fixes", "tracks", "events", "activity"], 0
    )
    assert store.last_seq() == 0 and len(store.store_id) == 16


def test_reopening_keeps_the_identity_and_the_rows(store, tmp_path):
    store.insert_batch([det(1.0)], report(1), "k")
    target = getattr(store, "url", None) or store.path
    again = open_store(target)
    try:
        assert again.store_id == store.store_id
        assert again.schema_version() == 7
        assert [i for i, _ in again.detections()] == [1]
    finally:
        again.close()


def test_a_batch_key_inserts_once(store):
    first = store.insert_batch([det(1.0), det(2.0)], report(2), "gw-1")
    again = store.insert_batch([det(9.0)], {"n_records": 1, "accepted": 1, "x": 1}, "gw-1")
    assert not first.duplicate and again.duplicate
    assert again.batch_id == first.batch_id and again.detection_ids == first.detection_ids == (1, 2)
    assert again.report == report(2)
    # a key repeated within one group commit, and keyless batches always insert
    out = store.insert_batches(
        [
            (lambda: ([det(3.0)], report(1)), "gw-2"),
            (lambda: ([det(4.0)], report(1)), "gw-2"),
            (lambda: ([det(5.0)], report(1)), None),
            (lambda: ([det(5.0)], report(1)), None),
        ]
    )
    assert [b.duplicate for b in out] == [False, True, False, False]
    assert [b.batch_id for b in out] == [2, 2, 3, 4]
    assert store.counts()["batches"] == 4 and store.counts()["detections"] == 5


def test_a_failing_batch_commits_nothing_and_numbers_go_on(store):
    store.insert_batch([det(1.0)], report(1), None)

    def boom():
        raise ValueError("no")

    with pytest.raises(ValueError):
        store.insert_batches([(lambda: ([det(2.0)], report(1)), "a"), (boom, "b")])
    assert store.counts()["batches"] == 1 and [i for i, _ in store.detections()] == [1]
    after = store.insert_batch([det(3.0)], report(1), "a")
    assert not after.duplicate and after.batch_id == 2 and after.detection_ids == (2,)


def test_detection_queries(store):
    store.insert_batch(
        [det(1.0), det(2.0, "cam2"), det(3.0, score=None), det(4.0, "cam2")], report(4), None
    )
    rows = store.detections(after_id=1, limit=2)
    assert [i for i, _ in rows] == [2, 3] and rows[1][1].score is None
    assert rows[0][1] == det(2.0, "cam2")
    win = store.detections_in_window(["cam2"], 1.5, 4.0)
    assert [i for i, _ in win] == [2, 4]
    assert store.last_times() == {"cam1": 3.0, "cam2": 4.0}
    assert store.sensor_counts() == {"cam1": 2, "cam2": 2}
    store.write_derived([(1, 1.0, "cam1", "human", "fix", {"detection_id": 1})], [], [])
    assert [i for i, _ in store.detections(unprocessed=True)] == [2, 3, 4]
    assert store.fixes() == [{"detection_id": 1}]


def test_derived_rows_tracks_activity_and_events(store):
    store.insert_batch([det(1.0)], report(1), None)
    seqs = store.write_derived(
        [(1, 1.0, "cam1", "human", "fix", {"detection_id": 1, "hits": []})],
        [track_row(1, [(0.0, 0.0), (1.0, 1.0)]), track_row(2, [(5.0, 5.0)], cls="vehicle")],
        [("fix", {"type": "fix", "n": 1}), ("event", {"type": "event", "kind": "x"})],
        activity=[
            {
                "key": "a",
                "kind": "loiter",
                "t_start_s": 0.0,
                "t_end_s": 1.0,
                "track_ids": [1],
                "open": True,
            }
        ],  # fmt: skip
    )
    assert [q for q, _ in seqs] == [1, 2] and seqs[1][1] == '{"type":"event","kind":"x"}'
    assert store.events_since(1) == [{"type": "event", "kind": "x", "seq": 2}]
    assert [t["id"] for t in store.tracks(cls="vehicle")] == [2]
    assert [t["id"] for t in store.tracks(bbox=(-1.0, -1.0, 0.5, 0.5))] == [1]
    assert [t["id"] for t in store.tracks(t_from=0.5, t_to=0.7)] == [1]
    # a tail write rewrites only the points from 1 on; the whole body reads back
    whole = [(0.0, 0.0), (1.5, 1.5), (2.0, 2.0)]
    known = {r[0]: r[1] for r in store.track_rows({})}
    store.write_derived([], [tail_row(1, whole, 1)], [])
    assert store.track(1) == track_row(1, whole)["body"]
    rows = {r[0]: r for r in store.track_rows(known, tails=True)}
    assert rows[2][2] is None  # unchanged: not read
    tail = rows[1][2]
    assert isinstance(tail, TrackTail) and tail.first == 1 and len(tail.points) == 2
    # activity upserts keep their id; a second key gets the next one
    body = {"key": "a", "kind": "loiter", "t_start_s": 0.0, "t_end_s": 5.0, "track_ids": [1],
            "open": False}  # fmt: skip
    store.write_derived([], [], [], activity=[body, {**body, "key": "b", "track_ids": [2]}])
    got = store.activity()
    assert [(a["key"], a["id"], a["t_end_s"]) for a in got] == [("a", 1, 5.0), ("b", 2, 5.0)]
    assert store.activity(open_only=True) == [] and len(store.latest_activity("loiter")) == 2
    # replacing the table keeps only the tracks asked for
    store.write_derived([], [track_row(3, [(9.0, 9.0)])], [], replace_tracks=True,
                        keep_track_ids=[2])  # fmt: skip
    assert [t["id"] for t in store.tracks()] == [2, 3] and store.counts()["tracks"] == 2
    assert store.track(2**70) is None and store.track(99) is None


def test_poses_ride_with_their_batch(store):
    poses = [
        ("cam1", 1.0, {"t_s": 1.0, "pan_deg": 3.0}),
        ("cam1", 2.0, {"t_s": 2.0, "pan_deg": 4.0}),
    ]
    store.insert_batches([(lambda: ([], {"n_records": 2, "accepted": 0}, poses), None)])
    store.insert_batches([(lambda: ([], report(0), [("cam2", 9.0, {"t_s": 9.0})]), None)])
    assert store.pose_last_times() == {"cam1": 2.0, "cam2": 9.0}
    assert store.poses("cam1", 1.5) == [{"t_s": 2.0, "pan_deg": 4.0}]
    assert store.recent_poses(5.0) == {
        "cam1": [{"t_s": 1.0, "pan_deg": 3.0}, {"t_s": 2.0, "pan_deg": 4.0}],
        "cam2": [{"t_s": 9.0}],
    }


def test_markers_and_their_messages(store):
    m, seq, text = add_marker(store, {"t_s": 1.0, "e_m": 5.0, "n_m": 6.0, "name": ""})
    assert m["id"] == 1 and m["name"] == "M1" and seq == 1
    add_marker(store, {"t_s": 2.0, "e_m": 1.0, "n_m": 1.0, "name": "b"})
    assert update_marker(store, 1, {"name": "gate"})[0]["name"] == "gate"
    assert update_marker(store, 9, {"name": "x"}) is None
    assert delete_marker(store, 2)[0] == 4 and delete_marker(store, 2) is None
    third, _, _ = add_marker(store, {"t_s": 3.0, "e_m": 0.0, "n_m": 0.0, "name": ""})
    assert third["id"] == 3  # never an id given before
    assert [x["id"] for x in list_markers(store)] == [1, 3] and store.last_seq() == 5
    assert [e["action"] for e in store.events_since(0)] == ["add", "add", "update", "delete", "add"]


def test_sqlite_takes_no_fence(tmp_path):
    s = open_store(tmp_path / "f.sqlite3")
    try:
        with pytest.raises(TypeError):
            s.write_derived([], [], [], fence=lambda c: None)
    finally:
        s.close()


def _workload(s) -> list:
    """A scripted run on ``s``; every read after every step (the twin test's record)."""
    seen: list = []

    def look():
        seen.append(
            (
                s.counts(), s.last_seq(), s.last_times(), s.sensor_counts(), s.detections(),
                s.detections(unprocessed=True), s.detections_in_window(["cam1", "cam2"], 0, 50),
                s.fixes(), s.events_since(0), s.tracks(), s.track_rows({}),
                s.track_rows({1: 1, 2: 2}, tails=True), s.activity(), s.latest_activity("loiter"),
                s.pose_last_times(), s.recent_poses(3.0), s.poses("cam1"), list_markers(s),
                [s.track(i) for i in range(5)],
            )
        )  # fmt: skip

    for k in range(6):
        poses = [("cam1", float(k), {"t_s": float(k), "pan_deg": k * 1.5})]
        s.insert_batches(
            [
                (lambda k=k, p=poses: ([det(k + 0.1), det(k + 0.2, "cam2")], report(2), p),
                 f"b{k}"),
                (lambda k=k: ([det(k + 0.5, score=None)], report(1)), f"b{k}" if k % 2 else None),
            ]
        )  # fmt: skip
        look()
        ids = [i for i, _ in s.detections(unprocessed=True)]
        fixes = [(i, 1.0 * i, "cam1", "human", "fix", {"detection_id": i, "hits": [
            {"e_m": float(i), "n_m": 2.0 * i}]}) for i in ids]  # fmt: skip
        line = [(float(j), float(j * j)) for j in range(k + 2)]
        tracks = [tail_row(1, line, max(0, k - 1)) if k else track_row(1, line)]
        if k % 2:
            tracks.append(track_row(2 + k % 3, line[:2], t0=k, cls="vehicle"))
        act = [{"key": f"loiter:{k % 2}", "kind": "loiter", "t_start_s": 0.0, "t_end_s": k * 1.0,
                "track_ids": [1 + k % 2], "open": k < 4, "p_enu": [1.0, 2.0, 0.0]}]  # fmt: skip
        s.write_derived(
            fixes, tracks, [("fix", {"type": "fix", "fix": fixes[0][5]}), ("event", {"k": k})],
            activity=act, replace_tracks=k == 4, keep_track_ids=[3] if k == 4 else (),
        )  # fmt: skip
        look()
        if k == 2:
            add_marker(s, {"t_s": 2.0, "e_m": 1.0, "n_m": 1.0, "name": ""})
            update_marker(s, 1, {"note": "n"})
        if k == 5:
            delete_marker(s, 1)
        look()
    return seen


def test_both_databases_give_the_same_answers(tmp_path, postgres_url):
    a, b = open_store(tmp_path / "twin.sqlite3"), open_store(postgres_url)
    try:
        sa, sb = _workload(a), _workload(b)
    finally:
        a.close()
        b.close()
    assert len(sa) == len(sb) == 18
    for k, (x, y) in enumerate(zip(sa, sb, strict=True)):
        assert repr(x) == repr(y), f"step {k}"
