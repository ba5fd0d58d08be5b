"""The test PostgreSQL server starts, gives fresh databases and has PostGIS."""

from __future__ import annotations

import psycopg


def test_fresh_database_has_postgis(postgres_url: str) -> None:
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute("CREATE EXTENSION IF NOT EXISTS postgis")
        (version,) = conn.execute("SELECT postgis_lib_version()").fetchone()
        (count,) = conn.execute(
            "SELECT count(*) FROM pg_tables WHERE schemaname = 'public'"
        ).fetchone()
    assert version.startswith("3.")
    assert count == 1  # postgis's spatial_ref_sys only


def test_databases_are_separate(postgres_cluster) -> None:
    a, b = postgres_cluster.create_database(), postgres_cluster.create_database()
    assert a != b
    with psycopg.connect(a, autocommit=True) as conn:
        conn.execute("CREATE TABLE only_here (x int)")
    with psycopg.connect(b) as conn:
        (n,) = conn.execute(
            "SELECT count(*) FROM pg_tables WHERE tablename = 'only_here'"
        ).fetchone()
    assert n == 0
