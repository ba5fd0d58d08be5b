"""The track cache behind ``/api/tracks`` and ``/api/synopsis``: cached answers = uncached ones.

Oracle: the answers computed from a fresh decode of every stored body (``Store.tracks``),
clipped pair by pair and split with :func:`trajectory_reference`, over a live ingest in
which tracks grow, end and have their tails revised by fixed-lag smoothing, and after a
restart that rewrites the tracks table.
"""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from server_helpers import AUTH, make_app, scenario_records, walk

from demtrack.core.site.folder import load_site
from demtrack.server import store as db
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.models import TracksOut
from demtrack.server.store.codec import loads_json
from demtrack.server.store.database import Store
from demtrack.server.synopsis import (
    assemble,
    trajectory,
    trajectory_reference,
)
from demtrack.server.synopsis_models import SynopsisOut
from demtrack.server.time_fields import track_with_times
from demtrack.server.track_cache import TrackCache
from demtrack.server.track_query import track_cache

pytestmark = pytest.mark.timeout(900)


def _ref_clip(track, t_from, t_to):
    pts = [
        p
        for p in track["points"]
        if (t_from is None or p["t_s"] >= t_from) and (t_to is None or p["t_s"] <= t_to)
    ]
    first = track["points"].index(pts[0]) if pts else 0
    return dict(track, points=pts, first_index=first)


def _ref_bodies(store, t_from, t_to):
    clipped = [_ref_clip(b, t_from, t_to) for b in store.tracks(t_from=t_from, t_to=t_to)]
    return [b for b in clipped if b["points"]]


def _ref_synopsis(store, t0, t1, step_s):
    trajs = [trajectory_reference(b, step_s) for b in _ref_bodies(store, t0, t1)]
    out = assemble(trajs, store.activity(t_from=t0, t_to=t1), t0, t1, False)
    return SynopsisOut.model_validate(out).model_dump(mode="json")


def _ref_tracks(store, t_from, t_to):
    # the answer carries each point's time_utc beside t_s (issue 27)
    out = {"tracks": [track_with_times(b) for b in _ref_bodies(store, t_from, t_to)]}
    return TracksOut.model_validate(out).model_dump(mode="json")


def _windows(t_end):
    # As the page asks: the last minute / 10 minutes / everything, step_s = span / 1500.
    return [(t_end - 5.0, t_end, 0.5), (t_end - 20.0, t_end - 2.0, 0.5), (None, t_end, 0.7)]


def _records(site, t_max):
    """The first ``t_max`` s of two scenarios, then one walk a minute later (tracks end)."""
    recs = walk(n=5, t0=t_max + 60.0)
    for name in ("vehicle-run", "pedestrians"):
        recs += scenario_records(site, name, t_max)
    return sorted(recs, key=lambda r: (r["t"], r["sensor"]))


def _check(c, t_end):
    store = c.app.state.console.store
    for t0, t1, step in _windows(t_end):
        q = {"t1": t1, "step_s": step} | ({} if t0 is None else {"t0": t0})
        r = c.get("/api/synopsis", headers=AUTH, params=q)
        assert r.status_code == 200
        assert r.json() == _ref_synopsis(store, t0, t1, step)
        q = {"t_to": t1} | ({} if t0 is None else {"t_from": t0})
        r = c.get("/api/tracks", headers=AUTH, params=q)
        assert r.status_code == 200
        assert r.json() == _ref_tracks(store, t0, t1)


def _revisions(before, after):
    """Tracks whose stored points changed where they were already stored (smoothing)."""
    n = 0
    for i, pts in after.items():
        old = before.get(i)
        if old is not None and pts[: len(old) - 1] != old[:-1] and len(pts) >= len(old):
            n += 1
    return n


def _points(store):
    return {b["id"]: b["points"] for b in store.tracks()}


def test_cached_answers_equal_uncached_over_live_ingest_and_restart(
    sample_site_dir, tmp_path, store_kw
):
    site = load_site(sample_site_dir)
    recs = _records(site, 40.0)
    seen = {"revised": 0, "ended": 0, "misses": 0}
    with TestClient(make_app(sample_site_dir, tmp_path, **store_kw)) as c:
        store = c.app.state.console.store
        k = 0
        prev = {}
        while k < len(recs):
            j = k
            while j < len(recs) and recs[j]["t"] < recs[k]["t"] + 1.0:
                j += 1
            r = c.post("/api/detections", headers=AUTH, json={"detections": recs[k:j]})
            assert r.status_code == 200
            _check(c, recs[j - 1]["t"])
            now = _points(store)
            seen["revised"] += _revisions(prev, now)
            prev = now
            k = j
        cache = track_cache(c.app.state.console)
        seen["ended"] = sum(not t["live"] for t in store.tracks())
        seen["misses"] = cache.misses
        assert cache.hits > 0
        # Exports read the same cached bodies; nothing may have changed them.
        for fmt in ("geojson", "csv", "gpx"):
            assert c.get(f"/api/tracks/export?format={fmt}", headers=AUTH).status_code == 200
        assert [t.body for t in cache.select()] == store.tracks()
        t_end = recs[-1]["t"]
    # The test exercised what it is about: revised tails, ended tracks, re-reads.
    assert seen["revised"] > 0 and seen["ended"] > 0 and seen["misses"] > len(prev)
    # a restart: the start-up replay rewrites
    with TestClient(make_app(sample_site_dir, tmp_path, **store_kw)) as c:
        _check(c, t_end)
        _check(c, t_end)  # now from the cache


def test_a_cache_outliving_a_tracks_rewrite_sees_the_new_bodies(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    recs = _records(site, 25.0)
    store = Store(tmp_path / "s.sqlite3")
    try:
        cache = TrackCache(store)
        p = Pipeline(site, store, "kalman", lambda _m: None)
        p.start()
        for k in range(0, len(recs), 40):
            p.ingest(recs[k : k + 40])
            assert [t.body for t in cache.select()] == store.tracks()
        revs = {i: r for i, r, _ in store.track_rows({})}
        q = Pipeline(site, store, "kalman", lambda _m: None)  # a restart: rewrites the table
        q.start()
        assert all(r > revs.get(i, -1) for i, r, _ in store.track_rows({}))
        assert [t.body for t in cache.select()] == store.tracks()
        assert [t.body for t in cache.select(t_from=5.0, t_to=9.0, cls="vehicle")] == (
            store.tracks(t_from=5.0, t_to=9.0, cls="vehicle")
        )
    finally:
        store.close()


def _row(i, body):
    return {
        "id": i,
        "cls": "human",
        "t_start": body["points"][0]["t_s"],
        "t_end": body["points"][-1]["t_s"],
        "e_min": 0.0,
        "n_min": 0.0,
        "e_max": 1.0,
        "n_max": 1.0,
        "sensors": ["cam1"],
        "live": body["live"],
        "body": body,
    }


def _body(i, n, live=True, shift=0.0):
    pts = [{"t_s": float(k), "e_m": k + shift, "n_m": 0.0, "sensors": ["cam1"]} for k in range(n)]
    return {"id": i, "cls": "human", "sensors": ["cam1"], "gaps": [], "live": live, "points": pts}


def test_an_old_database_migrates_and_every_write_moves_rev(tmp_path):
    path = tmp_path / "old.sqlite3"
    conn = db.connect(path)
    conn.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    for m in db.MIGRATIONS[:2]:  # a file written by demtrack before migration 3
        m(conn)
    conn.execute("INSERT INTO schema_version (version) VALUES (2)")
    conn.execute(
        "INSERT INTO tracks (id, cls, t_start, t_end, e_min, n_min, e_max, n_max, sensors,"
        " live, body) VALUES (1, 'human', 0, 2, 0, 0, 1, 1, '[\"cam1\"]', 0, ?)",
        (db.dumps_json(_body(1, 3, live=False)),),
    )
    conn.close()
    store = Store(path)
    try:
        assert store.schema_version() == len(db.MIGRATIONS) >= 3
        cache = TrackCache(store)
        assert [t.body for t in cache.select()] == store.tracks() == [_body(1, 3, live=False)]
        # migration 4 moved its points out of the row: that write gave it a version
        assert store.track_rows({})[0][:2] == (1, 1)
        store.write_derived([], [_row(2, _body(2, 4))], [])
        assert [t.body for t in cache.select()] == store.tracks()
        # Same length, same end, same point count: only the version tells them apart.
        store.write_derived([], [_row(2, _body(2, 4, shift=1.0))], [])
        assert [t.body for t in cache.select()] == store.tracks()
        assert cache.select()[1].body["points"][0]["e_m"] == 1.0
        store.write_derived([], [_row(2, _body(2, 4, shift=2.0))], [], replace_tracks=True)
        assert [t.body for t in cache.select()] == store.tracks()
        revs = [r for _, r, _ in store.track_rows({})]
        assert revs == sorted(set(revs)) and len(revs) == 1
    finally:
        store.close()


def test_cache_memory_is_bounded_and_answers_still_whole(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    try:
        rows = [_row(i, _body(i, 20 + i)) for i in range(1, 30)]
        store.write_derived([], rows, [])
        size = len(db.dumps_json(rows[0]["body"]))
        cache = TrackCache(store, max_bytes=5 * size)
        for _ in range(3):
            assert [t.body for t in cache.select()] == store.tracks()
            assert cache.nbytes <= cache.max_bytes and 0 < len(cache) <= 5
        with pytest.raises(ValueError, match="max_bytes"):
            TrackCache(store, max_bytes=-1)
    finally:
        store.close()


def _random_body(rng, n, ordered=True):
    t = np.cumsum(rng.choice([0.0, 0.1, 0.2, 0.5, 3.0], size=n))
    if not ordered:
        t = rng.permutation(t)
    pts = [
        {
            "t_s": float(tk),
            "e_m": float(rng.normal()),
            "n_m": float(rng.normal()),
            "u_m": 0.0,
            "lat_deg": 1.0,
            "lon_deg": 2.0,
            "h_m": 3.0,
            "sensors": sorted(rng.choice(["a", "b", "c"], size=rng.integers(1, 3), replace=False)),
        }
        for tk in t
    ]
    gaps = []
    for _ in range(rng.integers(0, 4)):
        a, b = sorted(rng.choice(t, size=2))
        gaps.append([float(a), float(b)])
    return {"id": 1, "cls": "human", "live": True, "gaps": gaps, "points": pts}


@pytest.mark.parametrize("seed", range(40))
def test_trajectory_equals_its_plain_twin(seed):
    rng = np.random.default_rng(seed)
    body = _random_body(rng, int(rng.integers(1, 200)), ordered=seed % 8 != 7)
    for step_s in (1e-3, 0.1, 0.3, 0.5, 1.0, 2.4, 1e3):
        assert trajectory(body, step_s) == trajectory_reference(body, step_s)


def test_cached_bodies_are_the_decoded_text(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    try:
        store.write_derived([], [_row(1, _body(1, 5))], [])
        cache = TrackCache(store)
        (t,) = cache.select()
        text = store.track_rows({})[0][2]
        assert t.body == loads_json(text) and t.nbytes == len(text) and t.in_order
        assert t.span(1.0, 3.0) == (1, 4) and t.span(10.0, None) == (5, 5)
        assert cache.select()[0] is t and cache.hits == 1 and cache.misses == 1
    finally:
        store.close()
