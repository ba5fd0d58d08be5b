"""The :class:`PostgresStore`: the console store on a PostgreSQL + PostGIS server.

One write connection and one read connection, each behind its own lock (the server calls
in from worker threads), as the SQLite store has. Writes run in one transaction each
(:meth:`PostgresStore._tx`); a detection batch is acknowledged only after its transaction
has committed with ``synchronous_commit=on`` (the WAL flushed to disk), derived rows
commit with ``synchronous_commit=off`` (SQLite's ``synchronous=NORMAL``: a crash of the
database server may lose the newest of them, which the start-up replay derives again).
Several processes may write one database: :meth:`PostgresStore.insert_batches` holds an
advisory lock to its commit, so batch and detection ids become visible in id order, and
the event log is numbered the same way (:mod:`.dialect`). Reads of several statements see
one snapshot (``REPEATABLE READ``).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import psycopg

from demtrack.core.tracking.types import Detection

from ...track_history import PointCuts
from ..batches import BatchMaker, StoredBatch, insert_batch_rows
from ..derived import FixRow, write_derived_rows
from ..dialect import Dialect
from ..integrity import StoreFullError, StoreUnreachableError
from ..reading import StoreReads
from . import schema
from .connection import QmarkConnection, connect, safe_url
from .dialect import BATCH_LOCK, POSTGRES

__all__ = ["Fence", "PostgresStore"]

#: A check run first inside a derived-write transaction (the tracker's lease: it raises
#: when this process no longer owns the site, and the transaction rolls back).
Fence = Callable[[psycopg.Connection[Any]], None]


class PostgresStore(StoreReads):
    """The console store on PostgreSQL (see the module docstring).

    Parameters
    ----------
    url : str
        ``postgresql://user[:password]@host[:port]/database``; the database must exist
        and the server have PostGIS (the first migration creates the extension).
    """

    dialect: Dialect = POSTGRES

    def __init__(self, url: str) -> None:
        #: The connection URL (its password, if any, is never printed: :attr:`safe_url`).
        self.url = url
        self.safe_url = safe_url(url)
        self._w = connect(url, application_name="demtrack-store")
        try:
            schema.migrate(self._w)
            #: The database's random identity (sent in the stream's ``hello``).
            self.store_id = schema.ensure_store_id(self._w)
            self._r = connect(url, application_name="demtrack-store-read")
        except BaseException:
            self._w.close()
            raise
        self._r.isolation_level = psycopg.IsolationLevel.REPEATABLE_READ
        self._r.read_only = True
        self._wq = QmarkConnection(self._w)
        self._rq = QmarkConnection(self._r)
        self._wlock = threading.Lock()
        self._rlock = threading.Lock()
        self._cuts = PointCuts()  # what each track write rewrote, for track_rows(tails=True)

    def close(self) -> None:
        """Close both connections."""
        with self._wlock, self._rlock:
            self._w.close()
            self._r.close()

    # ------------------------------------------------------------------ connections
    def _reconnect_writer(self) -> None:
        """A new write connection when the old one broke (the server restarted)."""
        if self._w.broken or self._w.closed:
            self._w = connect(self.url, application_name="demtrack-store")
            self._wq = QmarkConnection(self._w)

    def _reconnect_reader(self) -> None:
        if self._r.broken or self._r.closed:
            self._r = connect(self.url, application_name="demtrack-store-read")
            self._r.isolation_level = psycopg.IsolationLevel.REPEATABLE_READ
            self._r.read_only = True
            self._rq = QmarkConnection(self._r)

    # ------------------------------------------------------------------ writing
    def _tx(self, fn: Callable[[Any], Any], *, sync: bool = True) -> Any:
        """Run ``fn(connection)`` in one write transaction; ``sync=False``: no WAL flush wait.

        ``fn`` gets the ``?``-placeholder connection (:class:`.connection.QmarkConnection`;
        ``.raw`` is psycopg's). A full disk on the server is
        :class:`~demtrack.server.store.integrity.StoreFullError` (rolled back), a lost
        connection :class:`~demtrack.server.store.integrity.StoreUnreachableError` (the
        API answers 503; the next write opens a new connection).
        """
        with self._wlock:
            self._reconnect_writer()
            try:
                # Pipeline mode: statements whose results are not read go out without
                # waiting for the server (a transaction is a few round trips, not one per
                # statement); a read of a result waits for what was sent before it.
                with self._w.pipeline(), self._w.transaction():
                    if not sync:
                        self._w.execute("SET LOCAL synchronous_commit = off")
                    return fn(self._wq)
            except psycopg.errors.DiskFull:
                raise StoreFullError(
                    f"the database {self.safe_url} is full (no space left on the server's"
                    " disk): nothing was stored; retry once space is freed"
                ) from None
            except psycopg.OperationalError as exc:  # the server went away mid-write
                if not (self._w.broken or self._w.closed):
                    raise
                raise StoreUnreachableError(
                    f"the database {self.safe_url} cannot be reached"
                    f" ({' '.join(str(exc).split())[:200]}): nothing was stored; the next"
                    " write reconnects"
                ) from None

    def insert_batch(
        self, detections: Sequence[Detection], report: dict[str, Any], batch_key: str | None
    ) -> StoredBatch:
        """One batch in one committed transaction (see :meth:`insert_batches`)."""
        return self.insert_batches([(lambda: (detections, report), batch_key)])[0]

    def insert_batches(self, batches: Sequence[tuple[BatchMaker, str | None]]) -> list[StoredBatch]:
        """Several batches in one committed transaction: group commit.

        As :meth:`demtrack.server.store.database.SqliteStore.insert_batches`; the
        transaction first takes the advisory lock :data:`.dialect.BATCH_LOCK` (held to its
        commit), so writers in other processes wait, and ids are given and made visible in
        order.
        """

        def tx(c: QmarkConnection) -> list[StoredBatch]:
            c.execute("SELECT pg_advisory_xact_lock(?)", (BATCH_LOCK,))
            return insert_batch_rows(c, batches)  # type: ignore[arg-type]

        out: list[StoredBatch] = self._tx(tx)
        return out

    def write_derived(
        self,
        fixes: Iterable[FixRow],
        tracks: Iterable[dict[str, Any]],
        events: Iterable[tuple[str, Any]],
        *,
        replace_tracks: bool = False,
        keep_track_ids: Iterable[int] = (),
        activity: Iterable[dict[str, Any]] = (),
        fence: Fence | None = None,
    ) -> list[tuple[int, str]]:
        """Fixes, tracks, activity and events in one transaction (``synchronous_commit=off``).

        As :meth:`demtrack.server.store.database.SqliteStore.write_derived`. ``fence``
        (optional) is called with the psycopg connection inside the transaction before
        anything is written; if it raises, the transaction rolls back and the exception
        propagates.
        """
        track_list = list(tracks)

        def tx(c: QmarkConnection) -> list[tuple[int, str]]:
            if fence is not None:
                fence(c.raw)
            return write_derived_rows(
                c,
                self._cuts,
                fixes,
                track_list,
                events,
                replace_tracks=replace_tracks,
                keep_track_ids=keep_track_ids,
                activity=activity,
                dialect=self.dialect,
            )

        out: list[tuple[int, str]] = self._tx(tx, sync=False)
        return out

    # ------------------------------------------------------------------ reading
    @contextlib.contextmanager  # type: ignore[override]
    def _snapshot(self) -> Iterator[QmarkConnection]:
        """The read connection inside one ``REPEATABLE READ`` transaction."""
        with self._rlock:
            self._reconnect_reader()
            with self._r.transaction():
                yield self._rq

    def _rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        with self._rlock:
            self._reconnect_reader()
            try:
                return self._rq.execute(sql, params).fetchall()
            except psycopg.OperationalError:
                if not self._r.broken:
                    raise
            self._reconnect_reader()  # the server dropped the connection: once more
            return self._rq.execute(sql, params).fetchall()
