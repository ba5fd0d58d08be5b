from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from demtrack.server.messages import SCHEMA_PATH, messages_schema, schema_text
from demtrack.server.store import database as db

ROOT = Path(__file__).resolve().parents[2]


def test_exported_message_schema_is_current():
    path = ROOT / SCHEMA_PATH
    assert path.is_file(), "run: python -m demtrack.server.messages"
    assert path.read_text(encoding="utf-8") == schema_text(), (
        "web/schema/messages.json is stale; run: python -m demtrack.server.messages"
    )


def test_schema_is_a_discriminated_union_of_every_type():
    s = messages_schema()
    mapping = s["discriminator"]["mapping"]
    assert set(mapping) == set(s["x-server-types"]) | set(s["x-client-types"])
    assert s["discriminator"]["propertyName"] == "type"


def test_migrations_apply_once_and_refuse_a_newer_file(tmp_path):
    path = tmp_path / "x.sqlite3"
    store = db.Store(path)
    assert store.schema_version() == db.SCHEMA_VERSION == len(db.MIGRATIONS)
    store.close()
    conn = db.connect(path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    assert db.migrate(conn) == db.SCHEMA_VERSION  # nothing pending: no error, no change
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"detections", "fixes", "tracks", "events", "batches", "schema_version"} <= tables
    conn.execute("UPDATE schema_version SET version = 99")
    with pytest.raises(RuntimeError, match="newer"):
        db.migrate(conn)
    conn.close()


def test_a_failing_migration_rolls_back(tmp_path, monkeypatch):
    def broken(conn: sqlite3.Connection) -> None:
        conn.execute("CREATE TABLE half (x)")
        raise ValueError("boom")

    monkeypatch.setattr(db, "MIGRATIONS", (broken,))
    monkeypatch.setattr(db, "SCHEMA_VERSION", 1)
    conn = db.connect(tmp_path / "y.sqlite3")
    with pytest.raises(ValueError):
        db.migrate(conn)
    names = {r[0] for r in conn.execute("SELECT name FROM sqlite_master")}
    assert "half" not in names
    assert conn.execute("SELECT COUNT(*) FROM schema_version").fetchone()[0] == 0


def test_openapi_documents_every_route(ro_client):
    spec = ro_client.get("/openapi.json").json()
    for path in (
        "/api/site",
        "/api/site/relief.png",
        "/api/sensors",
        "/api/geolocate",
        "/api/geolocate/batch",
        "/api/detections",
        "/api/tracks",
        "/api/health",
    ):
        assert path in spec["paths"], path


def test_derived_rows_commit_without_a_sync_and_batches_with_one(tmp_path):
    from demtrack.core.tracking.types import Detection

    store = db.Store(tmp_path / "s.sqlite3")
    levels: list[int] = []
    real_tx = store._tx

    def spy(fn, **kw):
        def inner(c):
            levels.append(c.execute("PRAGMA synchronous").fetchone()[0])
            return fn(c)

        return real_tx(inner, **kw)

    store._tx = spy  # type: ignore[method-assign]
    det = Detection(0.0, "cam1", (10.0, 10.0, 20.0, 40.0), "human")
    store.insert_batch([det], {"n_records": 1, "accepted": 1}, None)
    store.write_derived([], [], [("event", {"type": "event", "kind": "x", "t_s": 0.0})])
    store.insert_batch([det], {"n_records": 1, "accepted": 1}, None)
    # FULL (2) for the durable batches, NORMAL (1) for derived rows, and FULL again after.
    assert levels == [2, 1, 2]
    assert store._w.execute("PRAGMA synchronous").fetchone()[0] == 2
    assert store.counts()["events"] == 1
    store.close()
