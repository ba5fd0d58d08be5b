"""Stored track bodies: points in rows of their own, only the changed ones rewritten.

A live track changes with almost every batch; writing its whole body each time made the
cost of a batch grow with the length of the tracks (about 13 kB of JSON per detection in a
20-track replay). The pipeline keeps each point's JSON and the store rewrites a track's
points only from the first that changed (new points, the smoother's revised tail).
Oracle: the body the store gives back after every batch is exactly the text of encoding the
pipeline's whole body at once, over a replay in which tracks grow, are smoothed and end.
"""

from __future__ import annotations

import itertools
import sqlite3
from typing import Any

import pytest
from server_helpers import scenario_stream

from demtrack.core.site.folder import load_site
from demtrack.server import store as db
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.store.codec import dumps_json, track_body_text
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def test_stored_bodies_equal_whole_encodings_and_only_changed_points_are_rewritten(
    sample_site_dir, tmp_path
):
    site = load_site(sample_site_dir)
    p = Pipeline(site, Store(tmp_path / "s.sqlite3"), "kalman", lambda _m: None)
    p.start()
    wholes: dict[int, str] = {}
    counts = {"rows": 0, "written": 0, "points": 0}
    track_body = p.track_body
    write = p.store.write_derived

    def body_spy(track: Any, live: bool, first_index: int = 0) -> dict[str, Any]:
        body = track_body(track, live, first_index)
        wholes[body["id"]] = dumps_json(body)
        return body

    def write_spy(fixes: Any, tracks: Any, events: Any, **kw: Any) -> list[int]:
        tracks = list(tracks)
        for r in tracks:
            counts["rows"] += 1
            counts["written"] += len(r["point_texts"])
            counts["points"] += r["points_from"] + len(r["point_texts"])
        return write(fixes, tracks, events, **kw)

    p.track_body = body_spy  # type: ignore[method-assign]
    p.store.write_derived = write_spy  # type: ignore[method-assign]
    frames = scenario_stream(site, ["passing-vehicles"], 0.0, rate_hz=5.0, duration_s=60.0)
    checked = 0
    for _, group in itertools.groupby(frames, key=lambda f: int(2 * f.t_s)):
        p.ingest([r for f in group for r in f.records])
        stored = {i: text for i, _, text in p.store.track_rows({})}
        for i, whole in wholes.items():
            assert stored[i] == whole
            checked += 1
        wholes.clear()
    assert checked > 50
    # Tracks were written again and again as they grew, but their points mostly once.
    assert counts["rows"] > 50
    assert counts["written"] < 0.25 * counts["points"]
    # The whole-body reads agree with the text reads.
    assert p.store.tracks() == [db.loads_json(t) for _, _, t in p.store.track_rows({})]


def test_whole_bodies_written_by_other_callers_round_trip(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    body = {"id": 3, "cls": "human", "points": [{"t_s": 1.0}, {"t_s": 2.0}], "live": True}
    row = dict(
        id=3, cls="human", t_start=1.0, t_end=2.0, e_min=0.0, n_min=0.0, e_max=1.0, n_max=1.0,
        sensors=["a"], live=True, body=body,
    )  # fmt: skip
    store.write_derived([], [row], [])
    assert store.track(3) == body
    store.write_derived([], [dict(row, body={**body, "points": [{"t_s": 5.0}]})], [])
    assert store.track(3)["points"] == [{"t_s": 5.0}]  # the longer old list is gone
    store.write_derived([], [], [], replace_tracks=True)
    assert store.track(3) is None and store.tracks() == []
    assert track_body_text("{}", ["1"]) == '{"points":[1]}'


def test_migration_4_moves_the_points_of_an_older_file(tmp_path):
    path = tmp_path / "old.sqlite3"
    conn = db.connect(path)
    conn.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    for m in db.MIGRATIONS[:3]:  # a file written by demtrack before migration 4
        m(conn)
    conn.execute("INSERT INTO schema_version (version) VALUES (3)")
    bodies = {
        1: {
            "id": 1,
            "cls": "car",
            "n_points": 2,
            "points": [{"t_s": 0.5, "e_m": 1.25}, {"t_s": 1}],
        },
        2: {"id": 2, "cls": "human", "points": []},
    }
    for i, b in bodies.items():
        conn.execute(
            "INSERT INTO tracks VALUES (?, ?, 0, 1, 0, 0, 1, 1, '[]', 0, ?)",
            (i, b["cls"], dumps_json(b)),
        )
    conn.close()
    store = Store(path)
    assert store.schema_version() == len(db.MIGRATIONS) >= 4
    assert store.counts()["tracks"] == 2  # counted by migration 5
    assert {t["id"]: t for t in store.tracks()} == bodies
    raw = sqlite3.connect(path).execute("SELECT body FROM tracks WHERE id = 1").fetchone()[0]
    assert "points" not in db.loads_json(raw)
