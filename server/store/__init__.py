"""Persistence: detections, fixes, tracks and the event log, in SQLite or PostgreSQL.

One interface (:class:`.backend.StoreBackend`), two databases: the SQLite file described
here (the default) and PostgreSQL + PostGIS (:mod:`.postgres`, selected by a database URL:
:func:`.opening.open_store`), with the same migrations, the same answers and the same
durability promise.

One file (WAL journal, ``synchronous=FULL``), a versioned schema with ordered migrations,
one write connection and one read connection, each behind its own lock (the server calls
in from worker threads). A detection batch is durable when :meth:`.database.Store.insert_batches`
returns: its transaction has committed and, with ``synchronous=FULL``, the WAL is synced.
Derived rows (fixes, tracks, events, activity) commit with ``synchronous=NORMAL``: no sync
of their own, so a batch costs one sync, not two. A killed process loses none of them (the
operating system holds the written WAL); after a power cut the newest of them may be gone,
and the start-up replay derives them again from the durable detections.

Tables
------
``schema_version``  the applied version (one row)
``store_identity``  the file's random ``store_id`` (one row, made at first open; the
                    stream's ``hello`` sends it: :mod:`.integrity`)
``batches``         one row per ingest request: optional client key, counts, report
``detections``      accepted detection records, id = arrival order
``fixes``           one per processed detection (derived: ray, every hit, status)
``tracks``          the tracker's tracks (derived; rewritten on start-up replay)
``events``          the WebSocket stream, ``seq`` = its sequence number
``activity``        detected events (loitering, rendezvous, convoy, zone crossings,
                    hand-off predictions, tracks confirmed / ended), one row per episode,
                    updated while it lasts (migration 2)
``track_rev``       a version per track, renewed by triggers whenever its row is written
                    (migration 3), so readers can cache decoded bodies by version
``track_points``    each track's points, one JSON text per row, ``k`` = index (migration
                    4); ``tracks.body`` holds the rest of the body. A live track's batch
                    rewrites only its points from the first that changed (new points and
                    the smoother's revised tail), not its whole history; readers get
                    the whole body back (:func:`.codec.track_body_text`), the same text as before.
``poses``           each sensor's pose telemetry, one JSON body per ``(sensor, t_s)``,
                    stored with the batch that carried it (migration 7; :mod:`.poses`)

Modules
-------
:mod:`.schema`     the tables, one function per migration
:mod:`.codec`      the JSON codec shared by the store and the stream
:mod:`.batches`    durable ingest batches (group commit)
:mod:`.poses`      pose telemetry rows
:mod:`.derived`    fixes, tracks, activity and event-log writes
:mod:`.queries`    read-side SQL
:mod:`.integrity`  the store's id, the file check before each write, a full disk
:mod:`.dialect`    the statements where SQLite and PostgreSQL differ (SQLite's)
:mod:`.reading`    every read, shared by both databases
:mod:`.database`   opening and migrating the file; :class:`~.database.SqliteStore` (``Store``)
:mod:`.backend`    the interface both stores have
:mod:`.opening`    :func:`~.opening.open_store`: the store the settings name
:mod:`.postgres`   the PostgreSQL + PostGIS store

May import ``demtrack.core`` value types and :mod:`demtrack.server.track_history`; nothing
here imports the ingest pipeline or the routers. Callers import from the modules; the
names below are the store's whole public surface in one place, for a reader (and the tests
of the file format) that wants it as one namespace.
"""

from __future__ import annotations

from .backend import StoreBackend
from .batches import StoredBatch
from .codec import dumps_json, encode_json, loads_json, published_text, track_body_text
from .database import MIGRATIONS, SCHEMA_VERSION, SqliteStore, Store, connect, migrate
from .queries import TrackTail
from .schema import COUNTED_TABLES

__all__ = [
    "COUNTED_TABLES",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "SqliteStore",
    "Store",
    "StoreBackend",
    "StoredBatch",
    "TrackTail",
    "connect",
    "dumps_json",
    "encode_json",
    "loads_json",
    "migrate",
    "published_text",
    "track_body_text",
]
