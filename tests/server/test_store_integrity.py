"""A full disk and a lost database file (issue 26, item 15); a lost PostgreSQL connection.

A full disk gave a 500 and a traceback: now 507 with one line, reads go on, and the next
batch after space returns is stored. A database file deleted or replaced while the server
ran kept being acknowledged (SQLite wrote on to the unlinked inode; a restart lost it
all): now every batch is refused (503) from then on, and the log says so, loudly.
The full disk is SQLite's own ``SQLITE_FULL``, made by capping the file's size
(``PRAGMA max_page_count``), which is what a filled disk gives SQLite too.
"""

from __future__ import annotations

import logging
import os
import shutil
import sqlite3

import pytest
from server_helpers import AUTH, walk

pytestmark = pytest.mark.timeout(180)


def post(client, **kw):
    return client.post("/api/detections", headers=AUTH, json={"detections": walk(**kw)})


@pytest.mark.sqlite_only("SQLite's own full disk: a page cap gives SQLITE_FULL")
def test_a_full_disk_is_507_reads_go_on_and_it_recovers(client, caplog):
    assert post(client, n=10).status_code == 200
    store = client.app.state.console.store
    w = store._w
    pages = w.execute("PRAGMA page_count").fetchone()[0]
    w.execute(f"PRAGMA max_page_count = {pages + 1}")
    caplog.set_level(logging.INFO, logger="demtrack.server")
    statuses = []
    for k in range(30):
        r = post(client, n=40, t0=10.0 + 10 * k, sensor="cam2")
        statuses.append(r.status_code)
        if r.status_code != 200:
            break
    assert statuses[-1] == 507, statuses
    detail = r.json()["detail"]
    assert "full" in detail and "nothing was stored" in detail and "\n" not in detail
    assert not [rec for rec in caplog.records if rec.exc_info], "no traceback for a full disk"
    assert any("full" in rec.getMessage() for rec in caplog.records)
    # reads keep serving
    assert client.get("/api/tracks", headers=AUTH).status_code == 200
    n_stored = len(client.get("/api/detections", headers=AUTH, params={"limit": 10000}).json())
    assert client.get("/api/health").status_code == 200
    # space returns: the next batch is stored
    w.execute("PRAGMA max_page_count = 1073741823")
    r = post(client, n=5, t0=1000.0, sensor="cam3")
    assert r.status_code == 200, r.text
    assert r.json()["accepted"] == 5
    listed = client.get("/api/detections", headers=AUTH, params={"limit": 10000}).json()
    assert len(listed) == n_stored + 5


def _db(client):
    return client.app.state.console.store.path


@pytest.mark.sqlite_only("the SQLite file unlinked under the server")
def test_a_deleted_database_file_stops_acknowledging_loudly(client, caplog):
    assert post(client, n=5).status_code == 200
    caplog.set_level(logging.INFO, logger="demtrack.server")
    os.remove(_db(client))
    for k in range(2):  # refused, and refused again: it never comes back by itself
        r = post(client, n=5, t0=10.0 + 10 * k)
        assert r.status_code == 503, r.text
        detail = r.json()["detail"]
        assert "deleted" in detail and "restart" in detail and "\n" not in detail
    critical = [rec for rec in caplog.records if rec.levelno >= logging.CRITICAL]
    assert len(critical) == 1 and "deleted" in critical[0].getMessage()
    assert client.get("/api/health").status_code == 200


@pytest.mark.sqlite_only("another SQLite file under the same name")
def test_a_replaced_database_file_stops_acknowledging(client, tmp_path):
    assert post(client, n=5).status_code == 200
    db = _db(client)
    copy = tmp_path / "copy.sqlite3"
    with sqlite3.connect(db) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)
    shutil.move(copy, db)  # another file under the same name (a restore, a mistake)
    r = post(client, n=5, t0=10.0)
    assert r.status_code == 503, r.text
    assert "replaced" in r.json()["detail"]


# The PostgreSQL meaning of losing the database: the server drops the console's connections
# (a restart of the database server, a failover, an administrator's pg_terminate_backend).
def test_a_lost_postgres_connection_is_503_and_the_next_batch_reconnects(
    sample_site_dir, tmp_path, postgres_cluster
):
    import psycopg
    from fastapi.testclient import TestClient
    from server_helpers import make_app

    url = postgres_cluster.create_store_database()
    with TestClient(make_app(sample_site_dir, tmp_path, database_url=url)) as c:
        assert post(c, n=5).status_code == 200
        with psycopg.connect(postgres_cluster.url, autocommit=True) as conn:
            conn.execute(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                " WHERE datname = %s AND pid <> pg_backend_pid()",
                (url.rsplit("/", 1)[1],),
            )
        r = post(c, n=5, t0=10.0)
        assert r.status_code == 503, r.text
        detail = r.json()["detail"]
        assert "cannot be reached" in detail and "\n" not in detail
        assert post(c, n=5, t0=10.0).status_code == 200  # the next one reconnects
        listed = c.get("/api/detections", headers=AUTH, params={"limit": 100}).json()
        assert [d["t"] for d in listed] == [d["t"] for d in walk(n=5) + walk(n=5, t0=10.0)]
        assert c.get("/api/health").status_code == 200
