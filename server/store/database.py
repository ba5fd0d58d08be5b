"""The console's SQLite file: opening and migrating it, and the :class:`Store` on it.

:class:`Store` is what the server holds: one write connection and one read connection,
each behind its own lock (the server calls in from worker threads). Writes run in one
transaction each (:meth:`Store._tx`), reads of several statements in one snapshot; the
SQL itself lives in :mod:`.batches`, :mod:`.derived` and :mod:`.queries`, the schema in
:mod:`.schema` (one function per migration; :data:`MIGRATIONS` puts them in order). See
the package docstring for the tables and durability.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from demtrack.core.tracking.types import Detection

from ..track_history import PointCuts
from . import schema
from .batches import BatchMaker, StoredBatch, insert_batch_rows
from .derived import FixRow, write_derived_rows
from .dialect import SQLITE
from .integrity import FileIdentity, ensure_store_id, translate_write_error
from .reading import StoreReads
from .schema import COUNTED_TABLES

# COUNTED_TABLES is the schema's: named here too, with the rest of what opens a file.
__all__ = [
    "COUNTED_TABLES",
    "MIGRATIONS",
    "SCHEMA_VERSION",
    "SqliteStore",
    "Store",
    "connect",
    "migrate",
]


#: Ordered migrations; applying ``MIGRATIONS[k]`` takes the schema from version k to k + 1.
MIGRATIONS: tuple[schema.Migration, ...] = (
    schema.m1_initial,
    schema.m2_activity,
    schema.m3_track_rev,
    schema.m4_track_points,
    schema.m5_row_counts,
    schema.m6_markers,
    schema.m7_poses,
)
SCHEMA_VERSION = len(MIGRATIONS)


def connect(path: Path) -> sqlite3.Connection:
    """Open ``path`` in WAL mode with ``synchronous=FULL`` (autocommit; explicit BEGINs).

    ``recursive_triggers`` is on: a row that ``INSERT OR REPLACE`` deletes fires the
    delete triggers (the row counts of ``row_counts`` and the revisions of ``track_rev``
    rely on every write going through a connection made here).
    """
    conn = sqlite3.connect(path, isolation_level=None, check_same_thread=False, timeout=30.0)
    conn.execute("PRAGMA journal_mode=WAL")
    conn.execute("PRAGMA synchronous=FULL")
    conn.execute("PRAGMA foreign_keys=ON")
    conn.execute("PRAGMA recursive_triggers=ON")
    return conn


def migrate(conn: sqlite3.Connection) -> int:
    """Apply the pending ``migrations``, each in its own transaction; return the new version.

    :data:`MIGRATIONS` is read when called: its length is the version the file is brought
    to (swapping it opens an older schema, as a test of upgrades does).

    Raises
    ------
    RuntimeError
        If the file's schema is newer than this demtrack knows.
    """
    migrations = MIGRATIONS
    target = len(migrations)
    conn.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)")
    row = conn.execute("SELECT version FROM schema_version").fetchone()
    version = 0 if row is None else int(row[0])
    if version > target:
        raise RuntimeError(
            f"database schema version {version} is newer than this demtrack ({target})"
        )
    for k in range(version, target):
        conn.execute("BEGIN IMMEDIATE")
        try:
            migrations[k](conn)
            conn.execute("DELETE FROM schema_version")
            conn.execute("INSERT INTO schema_version (version) VALUES (?)", (k + 1,))
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise
    return target


class SqliteStore(StoreReads):
    """The console's SQLite file (see :mod:`demtrack.server.store`).

    The reads are :class:`~.reading.StoreReads`'; :class:`~.postgres.database.PostgresStore`
    is the same surface on PostgreSQL (:class:`~.backend.StoreBackend`).
    """

    dialect = SQLITE

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._w = connect(self.path)
        migrate(self._w)
        #: The file's random identity (sent in the stream's ``hello``; :mod:`.integrity`).
        self.store_id = ensure_store_id(self._w)
        self._file = FileIdentity(self.path)
        self._r = connect(self.path)
        self._wlock = threading.Lock()
        self._rlock = threading.Lock()
        self._cuts = PointCuts()  # what each track write rewrote, for track_rows(tails=True)

    def close(self) -> None:
        """Close both connections."""
        with self._wlock, self._rlock:
            self._w.close()
            self._r.close()

    # ------------------------------------------------------------------ writing
    def _tx(self, fn: Callable[[sqlite3.Connection], Any], *, sync: bool = True) -> Any:
        """Run ``fn`` in one write transaction; ``sync=False``: commit without a WAL sync.

        Raises :class:`~.integrity.StoreLostError` (the file was deleted or replaced: no
        write is tried) or :class:`~.integrity.StoreFullError` (a full disk: rolled back).
        """
        with self._wlock:
            self._file.check()
            try:
                return self._tx_locked(fn, sync)
            except (sqlite3.Error, OSError) as exc:
                out = translate_write_error(exc, self.path)
                if out is exc:
                    raise
                raise out from None

    def _tx_locked(self, fn: Callable[[sqlite3.Connection], Any], sync: bool) -> Any:
        """:meth:`_tx` with the write lock held."""
        if not sync:
            self._w.execute("PRAGMA synchronous=NORMAL")
        try:
            self._w.execute("BEGIN IMMEDIATE")
            try:
                out = fn(self._w)
                self._w.execute("COMMIT")
            except BaseException:
                # SQLite may have rolled back itself (a full disk): only roll back if open
                if self._w.in_transaction:
                    self._w.execute("ROLLBACK")
                raise
        finally:
            if not sync:
                self._w.execute("PRAGMA synchronous=FULL")
        return out

    def insert_batch(
        self, detections: Sequence[Detection], report: dict[str, Any], batch_key: str | None
    ) -> StoredBatch:
        """Insert one batch and its accepted detections in one committed transaction.

        A ``batch_key`` seen before inserts nothing and returns the first report (so a
        client may safely resend a batch whose acknowledgement it lost).
        """
        return self.insert_batches([(lambda: (detections, report), batch_key)])[0]

    def insert_batches(
        self,
        batches: Sequence[tuple[BatchMaker, str | None]],
    ) -> list[StoredBatch]:
        """Insert several batches in one committed transaction (one WAL sync): group commit.

        Each entry is ``(make, batch_key)``; in order, a key seen before (in the file or
        earlier in this call) inserts nothing and gives the first report back, otherwise
        ``make()`` is called - inside the transaction, so it may depend on the batches
        before it - for the batch's accepted detections and report. All or none commit.
        """
        return self._tx(lambda c: insert_batch_rows(c, batches))

    def write_derived(
        self,
        fixes: Iterable[FixRow],
        tracks: Iterable[dict[str, Any]],
        events: Iterable[tuple[str, Any]],
        *,
        replace_tracks: bool = False,
        keep_track_ids: Iterable[int] = (),
        activity: Iterable[dict[str, Any]] = (),
        fence: None = None,
    ) -> list[tuple[int, str]]:
        """Store fixes, upsert tracks and activity, append events in one transaction.

        Parameters
        ----------
        fixes : iterable of (detection_id, t_s, sensor, cls, status, body)
        tracks : iterable of dict
            Track rows: ``id, cls, t_start, t_end, e_min, n_min, e_max, n_max, sensors
            (list), live (bool), body (dict, or its JSON text)``. Or, to rewrite only
            the points from one index on: ``body`` without ``points`` (its last key in
            the whole body) and ``points_from`` (int), ``point_texts`` (the JSON texts of
            the points from that index on; stored points beyond them are dropped).
        events : iterable of (type, payload)
            Payloads (dicts, or the typed structs of
            :mod:`demtrack.server.ingest.stream_messages`) without ``seq``; each gets the
            next sequence number.
        replace_tracks : bool
            Delete every stored track first, except those of ``keep_track_ids``.
        keep_track_ids : iterable of int
            With ``replace_tracks``: tracks left as they are (ended tracks the live
            tracker no longer holds).
        activity : iterable of dict
            Activity event bodies (``key, kind, t_start_s, t_end_s, track_ids, open``
            and the rest): inserted, or replacing the row with the same ``key`` (which
            keeps its ``id``); each body gets its row ``id`` filled in.
        fence : None
            PostgreSQL's store takes a check run inside the transaction
            (:meth:`~.postgres.database.PostgresStore.write_derived`); a file has one
            writer, so only None is accepted here.

        Returns
        -------
        list of (int, str)
            Each event's sequence number and stored JSON text (its payload, without
            ``seq``), in order: :func:`~.codec.published_text` makes the stream's text of it.

        Notes
        -----
        A fix body is encoded once: an event payload that holds one of this call's fix
        bodies as a value (the ``fix`` stream message) reuses that encoding.
        """
        if fence is not None:
            raise TypeError("a SQLite store has one writer: write_derived takes no fence")
        track_list = list(tracks)
        return self._tx(  # derived rows: sync=False, see the package docstring
            lambda c: write_derived_rows(
                c,
                self._cuts,
                fixes,
                track_list,
                events,
                replace_tracks=replace_tracks,
                keep_track_ids=keep_track_ids,
                activity=activity,
            ),
            sync=False,
        )

    # ------------------------------------------------------------------ reading
    @contextlib.contextmanager  # type: ignore[override]
    def _snapshot(self) -> Iterator[sqlite3.Connection]:
        """The read connection inside one read transaction: its reads see one snapshot."""
        with self._rlock:
            self._r.execute("BEGIN")
            try:
                yield self._r
            finally:
                self._r.execute("COMMIT")

    def _rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        with self._rlock:
            return self._r.execute(sql, params).fetchall()


#: The name the callers have always imported.
Store = SqliteStore
