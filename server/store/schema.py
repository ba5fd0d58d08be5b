"""The SQLite file's tables: one function per schema step (migration), in version order.

Each step takes the schema from one version to the next; :mod:`.database` lists them in
order (``MIGRATIONS``) and applies the pending ones, each in its own transaction. The
tables are described in :mod:`demtrack.server.store` (the package docstring).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable

__all__ = [
    "COUNTED_TABLES",
    "Migration",
    "m1_initial",
    "m2_activity",
    "m3_track_rev",
    "m4_track_points",
    "m5_row_counts",
    "m6_markers",
    "m7_poses",
]

#: One schema step: run inside the transaction :func:`migrate` opens.
Migration = Callable[[sqlite3.Connection], None]


def _run_script(conn: sqlite3.Connection, script: str) -> None:
    # Statement by statement: ``executescript`` would commit the migration's transaction.
    for stmt in script.split(";"):
        if stmt.strip():
            conn.execute(stmt)


def m1_initial(conn: sqlite3.Connection) -> None:
    """Version 1: batches, detections, fixes, tracks and the event log."""
    _run_script(
        conn,
        """
        CREATE TABLE batches (
            id INTEGER PRIMARY KEY,
            batch_key TEXT UNIQUE,
            n_records INTEGER NOT NULL,
            n_accepted INTEGER NOT NULL,
            report TEXT NOT NULL
        );
        CREATE TABLE detections (
            id INTEGER PRIMARY KEY,
            batch_id INTEGER NOT NULL REFERENCES batches(id),
            t_s REAL NOT NULL,
            sensor TEXT NOT NULL,
            u_min REAL NOT NULL, v_min REAL NOT NULL, u_max REAL NOT NULL, v_max REAL NOT NULL,
            cls TEXT NOT NULL,
            score REAL,
            local_id TEXT
        );
        CREATE INDEX detections_sensor_t ON detections(sensor, t_s);
        CREATE TABLE fixes (
            detection_id INTEGER PRIMARY KEY REFERENCES detections(id),
            t_s REAL NOT NULL,
            sensor TEXT NOT NULL,
            cls TEXT NOT NULL,
            status TEXT NOT NULL,
            body TEXT NOT NULL
        );
        CREATE TABLE tracks (
            id INTEGER PRIMARY KEY,
            cls TEXT NOT NULL,
            t_start REAL NOT NULL,
            t_end REAL NOT NULL,
            e_min REAL NOT NULL, n_min REAL NOT NULL, e_max REAL NOT NULL, n_max REAL NOT NULL,
            sensors TEXT NOT NULL,
            live INTEGER NOT NULL,
            body TEXT NOT NULL
        );
        CREATE TABLE events (
            seq INTEGER PRIMARY KEY AUTOINCREMENT,
            type TEXT NOT NULL,
            payload TEXT NOT NULL
        );
        """,
    )


def m2_activity(conn: sqlite3.Connection) -> None:
    """Version 2: the ``activity`` table (one row per detected episode)."""
    _run_script(
        conn,
        """
        CREATE TABLE activity (
            id INTEGER PRIMARY KEY,
            key TEXT NOT NULL UNIQUE,
            kind TEXT NOT NULL,
            t_start REAL NOT NULL,
            t_end REAL NOT NULL,
            track_ids TEXT NOT NULL,
            open INTEGER NOT NULL,
            body TEXT NOT NULL
        );
        CREATE INDEX activity_t ON activity(t_start, t_end);
        CREATE INDEX activity_kind ON activity(kind, t_start)
        """,
    )


def m3_track_rev(conn: sqlite3.Connection) -> None:
    """Version 3: ``track_rev``, a version per track renewed by triggers."""
    # ``track_rev``: per track, a number that changes whenever its row is written (given
    # by triggers, so the writers need not know; AUTOINCREMENT never reuses one), letting
    # a reader cache decoded bodies by ``(id, rev)``. A separate small table: setting a
    # column of ``tracks`` would rewrite the whole (large) row a second time. Tracks of an
    # older file have no row (rev 0) until they are written again.
    conn.execute("CREATE TABLE track_rev (rev INTEGER PRIMARY KEY AUTOINCREMENT, id INTEGER)")
    conn.execute("CREATE UNIQUE INDEX track_rev_id ON track_rev(id)")
    # Trigger bodies hold ``;``: one statement each, not through ``_run_script``. Delete,
    # then insert: no conflict, whatever policy the statement that fires them has.
    renew = " DELETE FROM track_rev WHERE id = NEW.id; INSERT INTO track_rev (id) VALUES (NEW.id);"
    conn.execute(f"CREATE TRIGGER track_rev_insert AFTER INSERT ON tracks BEGIN{renew} END")
    conn.execute(
        "CREATE TRIGGER track_rev_update AFTER UPDATE ON tracks BEGIN"
        f" DELETE FROM track_rev WHERE id = OLD.id;{renew} END"
    )
    conn.execute(
        "CREATE TRIGGER track_rev_delete AFTER DELETE ON tracks BEGIN"
        " DELETE FROM track_rev WHERE id = OLD.id; END"
    )


def m4_track_points(conn: sqlite3.Connection) -> None:
    """Version 4: ``track_points``, one row per track point (bodies split)."""
    # Points in rows of their own: a live track's body grew with its history and was
    # written whole on every batch (about 13 kB of JSON per detection in a 20-track
    # replay). Existing bodies are split: their points move here, the rest stays.
    conn.execute(
        "CREATE TABLE track_points (track_id INTEGER NOT NULL, k INTEGER NOT NULL,"
        " point TEXT NOT NULL, PRIMARY KEY (track_id, k)) WITHOUT ROWID"
    )
    conn.execute(
        "INSERT INTO track_points (track_id, k, point)"
        " SELECT tracks.id, p.key, p.value FROM tracks, json_each(tracks.body, '$.points') AS p"
    )
    conn.execute(
        "UPDATE tracks SET body = json_remove(body, '$.points')"
        " WHERE json_type(body, '$.points') IS NOT NULL"
    )


#: Tables whose rows ``Store.counts`` reports.
COUNTED_TABLES = ("batches", "detections", "fixes", "tracks", "events", "activity")


def m5_row_counts(conn: sqlite3.Connection) -> None:
    """Version 5: ``row_counts``, rows per table kept by triggers."""
    # Rows per table kept by triggers, so ``/api/status`` reads six numbers instead of
    # running COUNT(*) over tables of a million rows (about 1 s of CPU an hour into a 10x
    # replay, growing with the file). ``INSERT OR REPLACE`` fires the delete trigger for
    # the row it replaces only with ``recursive_triggers`` on (``connect`` sets it).
    conn.execute(
        "CREATE TABLE row_counts (name TEXT PRIMARY KEY, n INTEGER NOT NULL) WITHOUT ROWID"
    )
    for t in COUNTED_TABLES:
        conn.execute(f"INSERT INTO row_counts (name, n) SELECT '{t}', COUNT(*) FROM {t}")  # noqa: S608
        for when, sign in (("INSERT", "+"), ("DELETE", "-")):
            conn.execute(
                f"CREATE TRIGGER {t}_count_{when.lower()} AFTER {when} ON {t} BEGIN"
                f" UPDATE row_counts SET n = n {sign} 1 WHERE name = '{t}'; END"
            )


def m6_markers(conn: sqlite3.Connection) -> None:
    """Version 6: ``markers``, the points operators keep (one JSON body per row)."""
    # AUTOINCREMENT: a removed marker's id is never given to another, so a console that
    # still shows it cannot confuse the two.
    conn.execute(
        "CREATE TABLE markers (id INTEGER PRIMARY KEY AUTOINCREMENT, t_s REAL NOT NULL,"
        " body TEXT NOT NULL)"
    )


def m7_poses(conn: sqlite3.Connection) -> None:
    """Version 7: ``poses``, each sensor's pose telemetry (one JSON body per sample)."""
    # One row per (sensor, time): a sensor's poses go forwards in time (the ingest refuses
    # older ones), so the key is also the order the pipeline reloads them in. WITHOUT
    # ROWID: the key is the table's only index.
    conn.execute(
        "CREATE TABLE poses (sensor TEXT NOT NULL, t_s REAL NOT NULL,"
        " batch_id INTEGER NOT NULL REFERENCES batches(id), body TEXT NOT NULL,"
        " PRIMARY KEY (sensor, t_s)) WITHOUT ROWID"
    )
