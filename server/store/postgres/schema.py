"""The PostgreSQL database's tables: migrations 1..7, the SQLite file's, in PostgreSQL.

Each step has the meaning of the SQLite step of the same number
(:mod:`demtrack.server.store.schema`; the tables are described in the package docstring of
:mod:`demtrack.server.store`); the differences are PostgreSQL's types (``BIGINT``,
``DOUBLE PRECISION``), identity columns for ``AUTOINCREMENT``, statement-level triggers
for the row counts and track revisions (batch and activity ids are given by the
shared inserts, as SQLite gives them: the next one), and the PostGIS geometry columns (the site's
local metric frame, SRID 0: see :mod:`demtrack.server.store.postgres`), generated from the
stored JSON by the database itself, with their GiST indexes. :func:`migrate` applies the
pending steps, each in its own transaction, under an advisory lock (two processes starting
on one database migrate it once); :func:`ensure_store_id` gives the database its identity.
"""

from __future__ import annotations

import secrets
from collections.abc import Callable
from typing import Any

import psycopg

from ..schema import COUNTED_TABLES

__all__ = [
    "MIGRATE_LOCK",
    "MIGRATIONS",
    "Migration",
    "ensure_store_id",
    "migrate",
]

#: One schema step, run inside the transaction :func:`migrate` opens.
Migration = Callable[[psycopg.Connection[Any]], None]

#: The advisory lock (session level) held while a process migrates the database.
MIGRATE_LOCK = 0x64656D_0001

_F8 = "DOUBLE PRECISION"


def _point(json_expr: str, e: str, n: str) -> str:
    """A generated Point column's expression from two JSON paths of a text column."""
    return (
        f"geometry(Point) GENERATED ALWAYS AS (ST_MakePoint(({json_expr}::jsonb #>> '{e}')::float8,"
        f" ({json_expr}::jsonb #>> '{n}')::float8)) STORED"
    )


def _run(conn: psycopg.Connection[Any], script: str) -> None:
    # Several statements in one simple query (no parameters: psycopg sends it as it is).
    conn.execute(script.encode())


def m1_initial(conn: psycopg.Connection[Any]) -> None:
    """Version 1: batches, detections, fixes, tracks and the event log (and PostGIS)."""
    _run(
        conn,
        f"""
        CREATE EXTENSION IF NOT EXISTS postgis;
        CREATE TABLE batches (
            id BIGINT PRIMARY KEY,
            batch_key TEXT UNIQUE,
            n_records BIGINT NOT NULL,
            n_accepted BIGINT NOT NULL,
            report TEXT NOT NULL
        );
        CREATE TABLE detections (
            id BIGINT PRIMARY KEY,
            batch_id BIGINT NOT NULL REFERENCES batches(id),
            t_s {_F8} NOT NULL,
            sensor TEXT NOT NULL,
            u_min {_F8} NOT NULL, v_min {_F8} NOT NULL,
            u_max {_F8} NOT NULL, v_max {_F8} NOT NULL,
            cls TEXT NOT NULL,
            score {_F8},
            local_id TEXT
        );
        CREATE INDEX detections_sensor_t ON detections(sensor, t_s);
        CREATE INDEX detections_batch ON detections(batch_id);
        CREATE TABLE fixes (
            detection_id BIGINT PRIMARY KEY REFERENCES detections(id),
            t_s {_F8} NOT NULL,
            sensor TEXT NOT NULL,
            cls TEXT NOT NULL,
            status TEXT NOT NULL,
            body TEXT NOT NULL,
            geom {_point("body", "{hits,0,e_m}", "{hits,0,n_m}")}
        );
        CREATE INDEX fixes_geom ON fixes USING gist (geom);
        CREATE TABLE tracks (
            id BIGINT PRIMARY KEY,
            cls TEXT NOT NULL,
            t_start {_F8} NOT NULL,
            t_end {_F8} NOT NULL,
            e_min {_F8} NOT NULL, n_min {_F8} NOT NULL,
            e_max {_F8} NOT NULL, n_max {_F8} NOT NULL,
            sensors TEXT NOT NULL,
            live INTEGER NOT NULL,
            body TEXT NOT NULL
        );
        CREATE TABLE events (
            seq BIGINT PRIMARY KEY,
            type TEXT NOT NULL,
            payload TEXT NOT NULL
        )
        """,
    )


def m2_activity(conn: psycopg.Connection[Any]) -> None:
    """Version 2: the ``activity`` table (one row per detected episode; Point: ``p_enu``)."""
    _run(
        conn,
        f"""
        CREATE TABLE activity (
            id BIGINT PRIMARY KEY,
            key TEXT NOT NULL UNIQUE,
            kind TEXT NOT NULL,
            t_start {_F8} NOT NULL,
            t_end {_F8} NOT NULL,
            track_ids TEXT NOT NULL,
            open INTEGER NOT NULL,
            body TEXT NOT NULL,
            geom {_point("body", "{p_enu,0}", "{p_enu,1}")}
        );
        CREATE INDEX activity_t ON activity(t_start, t_end);
        CREATE INDEX activity_kind ON activity(kind, t_start);
        CREATE INDEX activity_geom ON activity USING gist (geom)
        """,
    )


def m3_track_rev(conn: psycopg.Connection[Any]) -> None:
    """Version 3: ``track_rev``, a version per track renewed by triggers."""
    # A sequence gives the versions (never reused); one statement-level trigger per event
    # (transition tables allow one event each) renews the rows the statement wrote.
    _run(
        conn,
        """
        CREATE SEQUENCE track_rev_seq;
        CREATE TABLE track_rev (id BIGINT PRIMARY KEY, rev BIGINT NOT NULL);
        CREATE FUNCTION track_rev_renew() RETURNS trigger LANGUAGE plpgsql AS $$
        BEGIN
            INSERT INTO track_rev (id, rev) SELECT id, nextval('track_rev_seq') FROM new_rows
            ON CONFLICT (id) DO UPDATE SET rev = EXCLUDED.rev;
            RETURN NULL;
        END $$;
        CREATE FUNCTION track_rev_drop() RETURNS trigger LANGUAGE plpgsql AS $$
        BEGIN
            DELETE FROM track_rev WHERE id IN (SELECT id FROM old_rows);
            RETURN NULL;
        END $$;
        CREATE TRIGGER track_rev_insert AFTER INSERT ON tracks REFERENCING NEW TABLE AS new_rows
            FOR EACH STATEMENT EXECUTE FUNCTION track_rev_renew();
        CREATE TRIGGER track_rev_update AFTER UPDATE ON tracks REFERENCING NEW TABLE AS new_rows
            FOR EACH STATEMENT EXECUTE FUNCTION track_rev_renew();
        CREATE TRIGGER track_rev_delete AFTER DELETE ON tracks REFERENCING OLD TABLE AS old_rows
            FOR EACH STATEMENT EXECUTE FUNCTION track_rev_drop()
        """,
    )


def m4_track_points(conn: psycopg.Connection[Any]) -> None:
    """Version 4: ``track_points`` (one row per point) and the tracks' LineStrings."""
    # No body of version 3 holds points on PostgreSQL's side of history (the store was
    # born at version 7), but the step splits them as SQLite's does, for the same meaning.
    _run(
        conn,
        f"""
        CREATE TABLE track_points (
            track_id BIGINT NOT NULL,
            k INTEGER NOT NULL,
            point TEXT NOT NULL,
            geom {_point("point", "{e_m}", "{n_m}")},
            PRIMARY KEY (track_id, k)
        );
        CREATE INDEX track_points_geom ON track_points USING gist (geom);
        INSERT INTO track_points (track_id, k, point)
            SELECT t.id, p.k - 1, p.value::text
            FROM tracks AS t, jsonb_array_elements(t.body::jsonb -> 'points')
                WITH ORDINALITY AS p(value, k)
            WHERE jsonb_typeof(t.body::jsonb -> 'points') = 'array';
        UPDATE tracks SET body = (body::jsonb - 'points')::text
            WHERE body::jsonb ? 'points';
        ALTER TABLE tracks ADD COLUMN geom geometry(LineString);
        CREATE INDEX tracks_geom ON tracks USING gist (geom);
        CREATE FUNCTION demtrack_track_line(old geometry, tid BIGINT, start INTEGER)
        RETURNS geometry LANGUAGE sql STABLE AS $$
            SELECT CASE WHEN count(*) >= 2 THEN ST_MakeLine(g ORDER BY o) END FROM (
                SELECT (dp).geom AS g, (dp).path[1] - 1 AS o FROM ST_DumpPoints(old) AS dp
                    WHERE ST_NPoints(old) >= start AND (dp).path[1] - 1 < start
                UNION ALL
                SELECT p.geom, p.k FROM track_points AS p WHERE p.track_id = tid
                    AND p.k >= CASE WHEN old IS NULL OR ST_NPoints(old) < start
                                    THEN 0 ELSE start END
            ) AS s
        $$
        """,
    )


def m5_row_counts(conn: psycopg.Connection[Any]) -> None:
    """Version 5: ``row_counts``, rows per table kept by (statement-level) triggers."""
    conn.execute("CREATE TABLE row_counts (name TEXT PRIMARY KEY, n BIGINT NOT NULL)")
    conn.execute(
        """
        CREATE FUNCTION row_counts_add() RETURNS trigger LANGUAGE plpgsql AS $$
        BEGIN
            IF EXISTS (SELECT 1 FROM new_rows) THEN  -- an upsert that only updated: no write
                UPDATE row_counts SET n = n + (SELECT count(*) FROM new_rows)
                    WHERE name = TG_TABLE_NAME;
            END IF;
            RETURN NULL;
        END $$
        """
    )
    conn.execute(
        """
        CREATE FUNCTION row_counts_sub() RETURNS trigger LANGUAGE plpgsql AS $$
        BEGIN
            IF EXISTS (SELECT 1 FROM old_rows) THEN  -- an upsert that only updated: no write
                UPDATE row_counts SET n = n - (SELECT count(*) FROM old_rows)
                    WHERE name = TG_TABLE_NAME;
            END IF;
            RETURN NULL;
        END $$
        """
    )
    for t in COUNTED_TABLES:
        conn.execute(f"INSERT INTO row_counts (name, n) SELECT '{t}', COUNT(*) FROM {t}")  # type: ignore[call-overload]  # noqa: S608
        conn.execute(  # type: ignore[call-overload]
            f"CREATE TRIGGER {t}_count_insert AFTER INSERT ON {t} REFERENCING NEW TABLE AS"
            " new_rows FOR EACH STATEMENT EXECUTE FUNCTION row_counts_add()"
        )
        conn.execute(  # type: ignore[call-overload]
            f"CREATE TRIGGER {t}_count_delete AFTER DELETE ON {t} REFERENCING OLD TABLE AS"
            " old_rows FOR EACH STATEMENT EXECUTE FUNCTION row_counts_sub()"
        )


def m6_markers(conn: psycopg.Connection[Any]) -> None:
    """Version 6: ``markers`` (an identity never reused; Point: ``e_m``, ``n_m``)."""
    _run(
        conn,
        f"""
        CREATE TABLE markers (
            id BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
            t_s {_F8} NOT NULL,
            body TEXT NOT NULL,
            geom {_point("body", "{e_m}", "{n_m}")}
        );
        CREATE INDEX markers_geom ON markers USING gist (geom)
        """,
    )


def m7_poses(conn: psycopg.Connection[Any]) -> None:
    """Version 7: ``poses``, each sensor's pose telemetry (one JSON body per sample)."""
    conn.execute(
        f"CREATE TABLE poses (sensor TEXT NOT NULL, t_s {_F8} NOT NULL,"
        " batch_id BIGINT NOT NULL REFERENCES batches(id), body TEXT NOT NULL,"
        " PRIMARY KEY (sensor, t_s))"
    )


#: Ordered migrations; ``MIGRATIONS[k]`` takes the schema from version k to k + 1.
MIGRATIONS: tuple[Migration, ...] = (
    m1_initial,
    m2_activity,
    m3_track_rev,
    m4_track_points,
    m5_row_counts,
    m6_markers,
    m7_poses,
)


def migrate(conn: psycopg.Connection[Any]) -> int:
    """Apply the pending migrations, each in its own transaction; return the new version.

    ``conn`` is in autocommit mode. :data:`MIGRATIONS` is read when called. Raises
    RuntimeError if the database's schema is newer than this demtrack knows.
    """
    migrations = MIGRATIONS
    target = len(migrations)
    conn.execute("SELECT pg_advisory_lock(%s)", (MIGRATE_LOCK,))
    try:
        conn.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)")
        row = conn.execute("SELECT version FROM schema_version").fetchone()
        version = 0 if row is None else int(row[0])
        if version > target:
            raise RuntimeError(
                f"database schema version {version} is newer than this demtrack ({target})"
            )
        for k in range(version, target):
            with conn.transaction():
                migrations[k](conn)
                conn.execute("DELETE FROM schema_version")
                conn.execute("INSERT INTO schema_version (version) VALUES (%s)", (k + 1,))
    finally:
        conn.execute("SELECT pg_advisory_unlock(%s)", (MIGRATE_LOCK,))
    return target


def ensure_store_id(conn: psycopg.Connection[Any]) -> str:
    """The database's random store id, made (and committed) on first call."""
    with conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATE_LOCK,))
        conn.execute("CREATE TABLE IF NOT EXISTS store_identity (store_id TEXT NOT NULL)")
        row = conn.execute("SELECT store_id FROM store_identity").fetchone()
        if row is not None:
            return str(row[0])
        store_id = secrets.token_hex(8)
        conn.execute("INSERT INTO store_identity (store_id) VALUES (%s)", (store_id,))
    return store_id
