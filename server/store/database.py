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
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from demtrack.core.tracking.types import Detection

from ..track_history import PointCuts
from . import schema
from .batches import BatchMaker, StoredBatch, insert_batch_rows
from .codec import loads_json, track_body_text
from .derived import FixRow, write_derived_rows
from .integrity import FileIdentity, ensure_store_id, translate_write_error
from .poses import pose_last_times, pose_rows_in_window, recent_pose_rows
from .queries import detection_row, points_of, read_track_rows, track_where, window_where
from .schema import COUNTED_TABLES

# COUNTED_TABLES is the schema's: named here too, with the rest of what opens a file.
__all__ = ["COUNTED_TABLES", "MIGRATIONS", "SCHEMA_VERSION", "Store", "connect", "migrate"]


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


class Store:
    """The console's SQLite file (see :mod:`demtrack.server.store`)."""

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
    @contextlib.contextmanager
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

    def schema_version(self) -> int:
        """The applied schema version."""
        return int(self._rows("SELECT version FROM schema_version")[0][0])

    def counts(self) -> dict[str, int]:
        """Rows per table (kept by triggers: no table is scanned)."""
        n = dict(self._rows("SELECT name, n FROM row_counts"))
        return {t: int(n[t]) for t in COUNTED_TABLES}

    def last_seq(self) -> int:
        """The newest event's sequence number (0 when there is none)."""
        return int(self._rows("SELECT COALESCE(MAX(seq), 0) FROM events")[0][0])

    def last_times(self) -> dict[str, float]:
        """Latest accepted detection time per sensor (s)."""
        return {
            s: float(t)
            for s, t in self._rows("SELECT sensor, MAX(t_s) FROM detections GROUP BY sensor")
        }

    def sensor_counts(self) -> dict[str, int]:
        """Accepted detections per sensor."""
        return {
            s: int(n)
            for s, n in self._rows("SELECT sensor, COUNT(*) FROM detections GROUP BY sensor")
        }

    def pose_last_times(self) -> dict[str, float]:
        """Each sensor's newest stored pose time (s)."""
        with self._rlock:
            return pose_last_times(self._r)

    def poses(
        self,
        sensor: str,
        t_from: float | None = None,
        t_to: float | None = None,
        limit: int = 1_000_000,
    ) -> list[dict[str, Any]]:
        """Stored pose bodies of ``sensor`` in ``[t_from, t_to]`` (s), in time order."""
        with self._rlock:
            return pose_rows_in_window(self._r, sensor, t_from, t_to, limit)

    def recent_poses(self, window_s: float) -> dict[str, list[dict[str, Any]]]:
        """Each sensor's pose bodies at most ``window_s`` behind its newest (start-up)."""
        with self._snapshot() as r:
            return recent_pose_rows(r, window_s)

    def detections(
        self, after_id: int = 0, limit: int = 1000, *, unprocessed: bool = False
    ) -> list[tuple[int, Detection]]:
        """Stored detections with ``id > after_id`` in id order (optionally unprocessed only)."""
        where = "d.id > ?" + (" AND f.detection_id IS NULL" if unprocessed else "")
        rows = self._rows(
            "SELECT d.id, d.t_s, d.sensor, d.u_min, d.v_min, d.u_max, d.v_max, d.cls, d.score,"
            " d.local_id FROM detections d LEFT JOIN fixes f ON f.detection_id = d.id"
            f" WHERE {where} ORDER BY d.id LIMIT ?",  # noqa: S608  (fixed clause)
            (after_id, limit),
        )
        return [detection_row(r) for r in rows]

    def detections_in_window(
        self,
        sensors: Sequence[str],
        t_from: float,
        t_to: float,
        after_id: int = 0,
        limit: int = 1000,
    ) -> list[tuple[int, Detection]]:
        """Detections of ``sensors`` with ``t_from <= t_s <= t_to``, by time then id.

        ``sensor IN (...) AND t_s`` range is answered from the ``(sensor, t_s)`` index.
        """
        marks = ",".join("?" * len(sensors))
        rows = self._rows(
            "SELECT id, t_s, sensor, u_min, v_min, u_max, v_max, cls, score, local_id"
            f" FROM detections WHERE sensor IN ({marks}) AND t_s >= ? AND t_s <= ? AND id > ?"
            " ORDER BY t_s, id LIMIT ?",  # noqa: S608  (placeholders only)
            (*sensors, t_from, t_to, after_id, limit),
        )
        return [detection_row(r) for r in rows]

    def fixes(self, after_id: int = 0, limit: int = 1000) -> list[dict[str, Any]]:
        """Stored fix bodies with ``detection_id > after_id``, in detection order."""
        rows = self._rows(
            "SELECT body FROM fixes WHERE detection_id > ? ORDER BY detection_id LIMIT ?",
            (after_id, limit),
        )
        return [loads_json(r[0]) for r in rows]

    def events_since(self, seq: int, limit: int = 1000) -> list[dict[str, Any]]:
        """Stream messages with ``seq > seq``, oldest first, ``seq`` filled in."""
        rows = self._rows(
            "SELECT seq, payload FROM events WHERE seq > ? ORDER BY seq LIMIT ?", (seq, limit)
        )
        return [{**loads_json(p), "seq": int(s)} for s, p in rows]

    def tracks(
        self,
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        cls: str | None = None,
        bbox: tuple[float, float, float, float] | None = None,
    ) -> list[dict[str, Any]]:
        """Track bodies overlapping a time window / class / ENU box, by id.

        Only the coarse test is made here (time span and bounding box overlap); the
        caller clips the points.
        """
        where, params = track_where(t_from, t_to, cls, bbox)
        with self._snapshot() as r:  # heads and points from one snapshot
            rows = r.execute(
                f"SELECT id, body FROM tracks{where} ORDER BY id",  # noqa: S608
                params,
            ).fetchall()
            points = points_of(r, [i for i, _ in rows])
        return [loads_json(track_body_text(head, points[i])) for i, head in rows]

    def track_rows(
        self,
        known: Mapping[int, int],
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        cls: str | None = None,
        bbox: tuple[float, float, float, float] | None = None,
        tails: bool = False,
    ) -> list[tuple[int, int, Any]]:
        """``(id, rev, body text)`` of the tracks :meth:`tracks` selects, by id.

        The text is None for a track whose ``rev`` is ``known[id]`` (the caller holds
        that version: ``rev``, from ``track_rev``, changes whenever the row is written),
        so only new and changed bodies are read. With ``tails``, a changed track whose
        writes since ``known[id]`` this store made (``server.track_history``) comes as a
        :class:`TrackTail` instead: its head and only the points from the first that
        changed. Both reads see one snapshot of the file.
        """
        where, params = track_where(t_from, t_to, cls, bbox)
        with self._snapshot() as r:
            return read_track_rows(r, known, where, params, self._cuts if tails else None)

    def track(self, track_id: int) -> dict[str, Any] | None:
        """The body of track ``track_id`` (None if there is none), by its primary key."""
        if not -(2**63) <= int(track_id) < 2**63:  # beyond SQLite's integers: no such track
            return None
        with self._snapshot() as r:
            rows = r.execute("SELECT body FROM tracks WHERE id = ?", (int(track_id),)).fetchall()
            points = points_of(r, [int(track_id)]) if rows else {}
        return loads_json(track_body_text(rows[0][0], points[int(track_id)])) if rows else None

    def activity(
        self,
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        kinds: Sequence[str] | None = None,
        open_only: bool = False,
        limit: int = 10_000,
    ) -> list[dict[str, Any]]:
        """Activity event bodies overlapping ``[t_from, t_to]``, of the kinds, by start time."""
        clauses, params = window_where(t_from, t_to)
        if kinds:
            clauses.append(f"kind IN ({','.join('?' * len(kinds))})")
            params += list(kinds)
        if open_only:
            clauses.append("open = 1")
        where = " WHERE " + " AND ".join(clauses) if clauses else ""
        rows = self._rows(
            f"SELECT body FROM activity{where} ORDER BY t_start, id LIMIT ?",  # noqa: S608
            [*params, limit],
        )
        return [loads_json(r[0]) for r in rows]

    def latest_activity(self, kind: str) -> list[dict[str, Any]]:
        """The newest event body of ``kind`` per first track id."""
        rows = self._rows(
            "SELECT body FROM activity WHERE id IN (SELECT MAX(id) FROM activity"
            " WHERE kind = ? GROUP BY json_extract(track_ids, '$[0]'))",
            (kind,),
        )
        return [loads_json(r[0]) for r in rows]
