"""What only the PostgreSQL store has: PostGIS columns, commit levels, notifications,
the fence, writers in several processes, and its start-up errors (one line, exit 2)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import psycopg
import pytest

from demtrack.core.errors import SettingsError
from demtrack.core.tracking.types import Detection
from demtrack.server.store.opening import open_store
from demtrack.server.store.postgres import schema as pg_schema
from demtrack.server.store.postgres.connection import safe_url
from demtrack.server.store.postgres.dialect import EVENT_CHANNEL

pytestmark = pytest.mark.timeout(300)


@pytest.fixture
def pg(postgres_url):
    s = open_store(postgres_url)
    yield s
    s.close()


def det(t: float) -> Detection:
    return Detection(t, "cam1", (10.0, 10.0, 20.0, 40.0), "human")


def _track(tid: int, pts: list[tuple[float, float]], **extra) -> dict:
    return {
        "id": tid, "cls": "human", "t_start": 0.0, "t_end": 1.0, "e_min": 0.0, "n_min": 0.0,
        "e_max": 1.0, "n_max": 1.0, "sensors": ["cam1"], "live": True,
        "body": {"id": tid, "points": [{"e_m": e, "n_m": n} for e, n in pts]}, **extra,
    }  # fmt: skip


def test_geometry_columns_follow_the_stored_json(pg, postgres_url):
    pg.insert_batch([det(0.0), det(1.0)], {"n_records": 2, "accepted": 2}, None)
    hit = {"e_m": 3.0, "n_m": 4.0, "u_m": 1.0}
    pg.write_derived(
        [(1, 0.0, "cam1", "human", "fix", {"hits": [hit]}), (2, 1.0, "cam1", "human", "none",
          {"hits": []})],
        [_track(1, [(0.0, 0.0), (1.0, 2.0)]), _track(2, [(7.0, 7.0)])],
        [],
        activity=[{"key": "a", "kind": "loiter", "t_start_s": 0.0, "t_end_s": 1.0,
                   "track_ids": [1], "open": True, "p_enu": [5.0, 6.0, 0.0]}],
    )  # fmt: skip
    # a tail rewrite: the line keeps its first point and takes the new ones
    tail = _track(1, [])
    tail["body"] = {"id": 1}
    tail.update(points_from=1, point_texts=['{"e_m":1.5,"n_m":1.5}', '{"e_m":2.0,"n_m":3.0}'])
    pg.write_derived([], [tail], [])
    from demtrack.server.store.markers import add_marker

    add_marker(pg, {"t_s": 1.0, "e_m": 8.0, "n_m": 9.0, "name": ""})
    with psycopg.connect(postgres_url) as c:
        q = lambda sql: c.execute(sql).fetchall()  # noqa: E731
        assert q("SELECT detection_id, ST_AsText(geom) FROM fixes ORDER BY 1") == [
            (1, "POINT(3 4)"), (2, None)
        ]  # fmt: skip
        assert q("SELECT id, ST_AsText(geom) FROM tracks ORDER BY 1") == [
            (1, "LINESTRING(0 0,1.5 1.5,2 3)"), (2, None)  # one point: no line
        ]  # fmt: skip
        assert q("SELECT ST_AsText(geom) FROM track_points WHERE track_id = 2") == [("POINT(7 7)",)]
        assert q("SELECT ST_AsText(geom) FROM activity") == [("POINT(5 6)",)]
        assert q("SELECT ST_AsText(geom) FROM markers") == [("POINT(8 9)",)]
        gist = {r[0] for r in q("SELECT tablename FROM pg_indexes WHERE indexdef LIKE '%gist%'")}
        assert gist == {"fixes", "tracks", "track_points", "activity", "markers"}
        # a spatial query the index serves: tracks crossing a box
        box = "ST_MakeEnvelope(1.8, 2.5, 2.2, 3.5)"
        assert q(f"SELECT id FROM tracks WHERE geom && {box}") == [(1,)]


def test_batches_commit_synchronously_and_derived_rows_do_not(pg):
    levels: list[str] = []
    real = pg._tx

    def spy(fn, **kw):
        def inner(c):
            levels.append(c.execute("SHOW synchronous_commit").fetchone()[0])
            return fn(c)

        return real(inner, **kw)

    pg._tx = spy
    pg.insert_batch([det(0.0)], {"n_records": 1, "accepted": 1}, None)
    pg.write_derived([], [], [("event", {"type": "event"})])
    pg.insert_batch([det(1.0)], {"n_records": 1, "accepted": 1}, None)
    assert levels == ["on", "off", "on"]


def test_events_are_notified_after_their_commit(pg, postgres_url):
    with psycopg.connect(postgres_url, autocommit=True) as listener:
        listener.execute(f"LISTEN {EVENT_CHANNEL}")
        seqs = pg.write_derived([], [], [("event", {"type": "a"}), ("event", {"type": "b"})])
        got = [n.payload for n in listener.notifies(timeout=5, stop_after=1)]
        assert got == [str(seqs[-1][0])] == ["2"]

        def fence(conn):
            conn.execute("SELECT 1")
            raise RuntimeError("lease lost")

        with pytest.raises(RuntimeError, match="lease lost"):
            pg.write_derived([], [], [("event", {"type": "c"})], fence=fence)
        assert list(listener.notifies(timeout=0.5)) == []  # rolled back: nothing announced
    assert pg.last_seq() == 2 and pg.counts()["events"] == 2


def test_a_fence_runs_first_inside_the_transaction(pg):
    seen = []

    def fence(conn):
        seen.append(conn.execute("SELECT count(*) FROM events").fetchone()[0])

    pg.write_derived([], [], [("event", {"type": "a"})], fence=fence)
    pg.write_derived([], [], [("event", {"type": "b"})], fence=fence)
    assert seen == [0, 1]


def test_writers_in_two_processes_make_ids_visible_in_order(postgres_url):
    """Two stores (two connections each) insert concurrently; a tailer reading
    ``detections(after_id=last)`` sees every id exactly once, in order."""
    writers = [open_store(postgres_url) for _ in range(2)]
    tailer = open_store(postgres_url)
    done = threading.Event()
    seen: list[int] = []

    def write(s, tag):
        for k in range(40):
            s.insert_batch([det(k), det(k + 0.5)], {"n_records": 2, "accepted": 2}, f"{tag}{k}")
            s.write_derived([], [], [("event", {"type": "e", "w": tag})])

    def tail():
        last = 0
        while True:
            stop = done.is_set()
            rows = tailer.detections(after_id=last, limit=1000)
            for i, _ in rows:
                seen.append(i)
                last = i
            if stop and not rows:
                return

    try:
        t = threading.Thread(target=tail)
        t.start()
        ws = [
            threading.Thread(target=write, args=(s, tag))
            for s, tag in zip(writers, "ab", strict=True)
        ]
        for w in ws:
            w.start()
        for w in ws:
            w.join()
        done.set()
        t.join(60)
        assert seen == list(range(1, 161))
        assert [e["seq"] for e in tailer.events_since(0, 1000)] == list(range(1, 81))
        assert tailer.counts()["batches"] == 80
    finally:
        for s in (*writers, tailer):
            s.close()


def test_migrations_refuse_a_newer_database_and_roll_back_a_failing_step(
    postgres_cluster, monkeypatch
):
    url = postgres_cluster.create_database()
    open_store(url).close()
    with psycopg.connect(url, autocommit=True) as c:
        c.execute("UPDATE schema_version SET version = 99")
    with pytest.raises(SettingsError, match="newer"):
        open_store(url)

    def broken(conn):
        conn.execute("CREATE TABLE half (x int)")
        raise ValueError("boom")

    url = postgres_cluster.create_database()
    monkeypatch.setattr(pg_schema, "MIGRATIONS", (pg_schema.m1_initial, broken))
    with pytest.raises(ValueError, match="boom"):
        open_store(url)
    with psycopg.connect(url) as c:
        assert c.execute("SELECT version FROM schema_version").fetchall() == [(1,)]
        assert c.execute("SELECT to_regclass('half')").fetchone() == (None,)


def test_urls_are_printed_without_their_password():
    assert safe_url("postgresql://u:s3cret@h:5433/db") == "postgresql://u:***@h:5433/db"
    assert safe_url("postgresql://u@h/db") == "postgresql://u@h/db"
    assert "s3cret" not in safe_url("postgresql://u:s3cret@h:notaport/db")


def _serve(site: Path, tmp: Path, url: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DEMTRACK_TOKEN": "t", "DEMTRACK_DATABASE_URL": url}
    return subprocess.run(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(site), "--db",
         str(tmp / "c.sqlite3"), "--port", "0", "--no-warm-up"],
        capture_output=True, text=True, check=False, timeout=240, env=env,
    )  # fmt: skip


def _no_postgis_url(cluster) -> str:
    """A database whose role may not create the PostGIS extension (not a superuser)."""
    url = cluster.create_database("np")
    name = url.rsplit("/", 1)[1]
    with psycopg.connect(cluster.url, autocommit=True) as c:
        c.execute("DROP ROLE IF EXISTS plain")
        c.execute("CREATE ROLE plain LOGIN PASSWORD 'hunter2'")
        c.execute(f'GRANT ALL ON DATABASE "{name}" TO plain')
    with psycopg.connect(url, autocommit=True) as c:
        c.execute("GRANT ALL ON SCHEMA public TO plain")
    return f"postgresql://plain:hunter2@127.0.0.1:{cluster.port}/{name}"


@pytest.mark.parametrize("case", ["unreachable", "malformed", "no_postgis"])
def test_a_database_that_cannot_be_used_is_one_line(
    case, sample_site_dir, tmp_path, postgres_cluster
):
    url = {
        "unreachable": "postgresql://u:hunter2@127.0.0.1:1/db",
        "malformed": "postgresql://u:hunter2@127.0.0.1:notaport/db",
        "no_postgis": None,
    }[case] or _no_postgis_url(postgres_cluster)
    proc = _serve(sample_site_dir, tmp_path, url)
    err = proc.stderr
    assert proc.returncode == 2, err[-3000:]
    assert err.count("\n") == 1 and err.startswith("demtrack "), err[-3000:]
    assert "Traceback" not in err and "hunter2" not in err + proc.stdout, err
    assert "postgresql://" in err and ("***" in err), err
    if case == "no_postgis":
        assert "postgis" in err.lower(), err


def test_a_lost_connection_refuses_one_write_and_the_next_reconnects(pg, postgres_url):
    from demtrack.server.store.integrity import StoreUnreachableError

    pg.insert_batch([det(0.0)], {"n_records": 1, "accepted": 1}, "a")
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        admin.execute(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
            " WHERE application_name LIKE 'demtrack-store%%' AND datname = current_database()"
        )
    with pytest.raises(StoreUnreachableError, match="cannot be reached"):
        pg.insert_batch([det(1.0)], {"n_records": 1, "accepted": 1}, "b")
    again = pg.insert_batch([det(1.0)], {"n_records": 1, "accepted": 1}, "b")
    assert not again.duplicate and again.detection_ids == (2,)  # nothing of the refused one
    assert [i for i, _ in pg.detections()] == [1, 2]  # the reader reconnects too
