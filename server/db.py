"""SQLite persistence: detections, fixes, tracks and the event log.

One file (WAL journal, ``synchronous=FULL``), a versioned schema with ordered migrations,
one write connection and one read connection, each behind its own lock (the server calls
in from worker threads). A detection batch is durable when :meth:`Store.insert_batches`
returns: its transaction has committed and, with ``synchronous=FULL``, the WAL is synced.
Derived rows (fixes, tracks, events, activity) commit with ``synchronous=NORMAL``: no sync
of their own, so a batch costs one sync, not two. A killed process loses none of them (the
operating system holds the written WAL); after a power cut the newest of them may be gone,
and the start-up replay derives them again from the durable detections.

Tables
------
``schema_version``  the applied version (one row)
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
                    the whole body back (:func:`track_body_text`), the same text as before.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from demtrack.core.tracking.types import Detection

from .track_history import PointCuts

__all__ = [
    "COUNTED_TABLES",
    "MIGRATIONS",
    "TrackTail",
    "SCHEMA_VERSION",
    "Store",
    "StoredBatch",
    "connect",
    "dumps_json",
    "encode_json",
    "loads_json",
    "migrate",
    "published_text",
    "track_body_text",
]


def _run_script(conn: sqlite3.Connection, script: str) -> None:
    # Statement by statement: ``executescript`` would commit the migration's transaction.
    for stmt in script.split(";"):
        if stmt.strip():
            conn.execute(stmt)


def _m1_initial(conn: sqlite3.Connection) -> None:
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


def _m2_activity(conn: sqlite3.Connection) -> None:
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


def _m3_track_rev(conn: sqlite3.Connection) -> None:
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


def _m4_track_points(conn: sqlite3.Connection) -> None:
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


def _m5_row_counts(conn: sqlite3.Connection) -> None:
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


#: Ordered migrations; applying ``MIGRATIONS[k]`` takes the schema from version k to k + 1.
MIGRATIONS: tuple[Callable[[sqlite3.Connection], None], ...] = (
    _m1_initial,
    _m2_activity,
    _m3_track_rev,
    _m4_track_points,
    _m5_row_counts,
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
    """Apply the pending migrations, each in its own transaction; return the new version.

    Raises
    ------
    RuntimeError
        If the file's schema is newer than this demtrack knows.
    """
    conn.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)")
    row = conn.execute("SELECT version FROM schema_version").fetchone()
    version = 0 if row is None else int(row[0])
    if version > SCHEMA_VERSION:
        raise RuntimeError(
            f"database schema version {version} is newer than this demtrack ({SCHEMA_VERSION})"
        )
    for k in range(version, SCHEMA_VERSION):
        conn.execute("BEGIN IMMEDIATE")
        try:
            MIGRATIONS[k](conn)
            conn.execute("DELETE FROM schema_version")
            conn.execute("INSERT INTO schema_version (version) VALUES (?)", (k + 1,))
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise
    return SCHEMA_VERSION


@dataclass(frozen=True)
class TrackTail:
    """What changed in a track's stored body since a version the reader holds.

    ``head``: the body without ``points`` (JSON text); ``first``: the index of the first
    point that changed; ``points``: the JSON texts of the points from ``first`` on (the
    stored points before ``first`` are those of the reader's version).
    """

    head: str
    first: int
    points: list[str]


@dataclass(frozen=True)
class StoredBatch:
    """A committed ingest batch.

    Attributes
    ----------
    batch_id : int
    detection_ids : tuple of int
        Ids of its accepted detections, in record order.
    report : dict
        The acknowledgement sent for it (returned again for a repeated ``batch_key``).
    duplicate : bool
        The key had been seen: nothing was inserted this time.
    """

    batch_id: int
    detection_ids: tuple[int, ...]
    report: dict[str, Any]
    duplicate: bool = False


_ENCODER = msgspec.json.Encoder()
_DECODER = msgspec.json.Decoder()


def dumps_json(obj: Any) -> str:
    """Compact JSON: how every stored body and stream message is encoded.

    msgspec's encoder (about 9x faster than :func:`json.dumps` on fix and track bodies):
    the same text as ``json.dumps(obj, separators=(",", ":"))`` except that exponents
    carry no ``+`` (``1e21``) and NaN or infinities become ``null`` (JSON has neither;
    the server's numbers are finite by construction).
    """
    return encode_json(obj).decode()


def encode_json(obj: Any) -> bytes:
    """:func:`dumps_json`'s text as UTF-8 bytes (one msgspec encoder for the whole server)."""
    return _ENCODER.encode(obj)


def published_text(stored: str, seq: int) -> str:
    """The stream's text of a stored event payload: ``dumps_json({**payload, "seq": seq})``.

    The stored text is the payload's encoding (a JSON object without ``seq``); the key goes
    last, as the dict merge puts it, so the text is the same without encoding it again.
    """
    return f'{stored[:-1]},"seq":{int(seq)}}}' if stored != "{}" else f'{{"seq":{int(seq)}}}'


def _encode_reusing(payload: dict[str, Any], encoded: dict[int, tuple[Any, bytes]]) -> str:
    """``dumps_json(payload)``, reusing encodings of values already encoded.

    ``encoded`` maps ``id(object) -> (object, its JSON)``; a payload value that is one of
    those objects (by identity) is inserted as that JSON, not encoded again.
    """
    if any(id(v) in encoded for v in payload.values()):
        payload = {
            k: msgspec.Raw(encoded[id(v)][1]) if id(v) in encoded else v for k, v in payload.items()
        }
    return dumps_json(payload)


def loads_json(text: str | bytes) -> Any:
    """Parse a stored body (msgspec's decoder: the values :func:`json.loads` gives, ~3.5x faster).

    Stored track bodies are read back on every track, synopsis and export request; with
    :func:`json.loads` their decoding was the largest single cost of the console server
    under a live replay.
    """
    return _DECODER.decode(text)


def _next_id(c: sqlite3.Connection, sql: str) -> int:
    """One more than the integer ``sql`` selects (1 when it selects nothing or NULL)."""
    row = c.execute(sql).fetchone()
    return 1 if row is None or row[0] is None else int(row[0]) + 1


#: A track row's version (see migration 3); 0 for a row written before it.
_REV = "COALESCE((SELECT rev FROM track_rev WHERE track_rev.id = tracks.id), 0)"


def track_body_text(head: str, points: Sequence[str]) -> str:
    """A track's whole body as JSON: its stored head with ``points`` as the last key.

    The same text as encoding the whole body at once when ``points`` was its last key
    (as in every body the server writes).
    """
    sep = "," if head != "{}" else ""
    return f'{head[:-1]}{sep}"points":[{",".join(points)}]}}'


def _split_track_body(row: Mapping[str, Any]) -> tuple[str, list[str], int]:
    """A track row's head text, point texts and the index its points start at.

    Rows either give the split form (``points_from`` and ``point_texts``: points from
    that index on, ``body`` without points) or a whole ``body`` (dict or JSON text).
    """
    body = row["body"]
    if "points_from" in row:
        head = body if isinstance(body, str) else dumps_json(body)
        return head, list(row["point_texts"]), int(row["points_from"])
    if isinstance(body, str):
        body = loads_json(body)
    head = dumps_json({k: v for k, v in body.items() if k != "points"})
    return head, [dumps_json(p) for p in body.get("points", ())], 0


def _id_chunks(ids: Sequence[int], size: int = 500) -> Iterator[tuple[list[int], str]]:
    """``ids`` in chunks, each with its ``?,?,...`` placeholders for an ``IN (...)``."""
    for k in range(0, len(ids), size):
        chunk = list(ids[k : k + size])
        yield chunk, ",".join("?" * len(chunk))


def _track_revs(c: sqlite3.Connection, ids: Sequence[int]) -> dict[int, int]:
    """The current ``track_rev`` of tracks ``ids`` (those that have one)."""
    out: dict[int, int] = {}
    for chunk, marks in _id_chunks(ids):
        out.update(c.execute(f"SELECT id, rev FROM track_rev WHERE id IN ({marks})", chunk))  # noqa: S608
    return out


def _points_of(c: sqlite3.Connection, ids: Sequence[int]) -> dict[int, list[str]]:
    """The stored point texts of tracks ``ids``, in order (an empty list for none)."""
    out: dict[int, list[str]] = {i: [] for i in ids}
    for chunk, marks in _id_chunks(ids):
        for tid, point in c.execute(
            f"SELECT track_id, point FROM track_points WHERE track_id IN ({marks})"  # noqa: S608
            " ORDER BY track_id, k",
            chunk,
        ):
            out[tid].append(point)
    return out


def _window_where(t_from: float | None, t_to: float | None) -> tuple[list[str], list[float | str]]:
    """Clauses and parameters selecting rows whose ``[t_start, t_end]`` meets the window."""
    clauses: list[str] = []
    params: list[float | str] = []
    if t_from is not None:
        clauses.append("t_end >= ?")
        params.append(t_from)
    if t_to is not None:
        clauses.append("t_start <= ?")
        params.append(t_to)
    return clauses, params


def _track_where(
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    bbox: tuple[float, float, float, float] | None,
) -> tuple[str, list[float | str]]:
    """The ``WHERE`` clause and parameters of a track selection (time, class, box overlap)."""
    clauses, params = _window_where(t_from, t_to)
    if cls is not None:
        clauses.append("cls = ?")
        params.append(cls)
    if bbox is not None:
        clauses += ["e_max >= ?", "n_max >= ?", "e_min <= ?", "n_min <= ?"]
        params += list(bbox)
    return (" WHERE " + " AND ".join(clauses) if clauses else ""), params


def _detection_row(r: Sequence[Any]) -> tuple[int, Detection]:
    """``(id, Detection)`` of a detections row read in its column order.

    Columns: ``id, t_s, sensor, u_min, v_min, u_max, v_max, cls, score, local_id``.
    """
    return r[0], Detection(r[1], r[2], (r[3], r[4], r[5], r[6]), r[7], r[8], r[9])


class Store:
    """The console's SQLite file (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._w = connect(self.path)
        migrate(self._w)
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
        """Run ``fn`` in one write transaction; ``sync=False``: commit without a WAL sync."""
        with self._wlock:
            if not sync:
                self._w.execute("PRAGMA synchronous=NORMAL")
            try:
                self._w.execute("BEGIN IMMEDIATE")
                try:
                    out = fn(self._w)
                    self._w.execute("COMMIT")
                except BaseException:
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
        batches: Sequence[
            tuple[Callable[[], tuple[Sequence[Detection], dict[str, Any]]], str | None]
        ],
    ) -> list[StoredBatch]:
        """Insert several batches in one committed transaction (one WAL sync): group commit.

        Each entry is ``(make, batch_key)``; in order, a key seen before (in the file or
        earlier in this call) inserts nothing and gives the first report back, otherwise
        ``make()`` is called - inside the transaction, so it may depend on the batches
        before it - for the batch's accepted detections and report. All or none commit.
        """

        def run(c: sqlite3.Connection) -> list[StoredBatch]:
            out = []
            for make, batch_key in batches:
                if batch_key is not None:
                    row = c.execute(
                        "SELECT id, report FROM batches WHERE batch_key = ?", (batch_key,)
                    ).fetchone()
                    if row is not None:
                        known = tuple(
                            int(r[0])
                            for r in c.execute(
                                "SELECT id FROM detections WHERE batch_id = ? ORDER BY id",
                                (row[0],),
                            )
                        )
                        out.append(StoredBatch(row[0], known, loads_json(row[1]), duplicate=True))
                        continue
                detections, report = make()
                # One statement gives the batch's id and the detections' highest id.
                ((batch_id, last_id),) = c.execute(
                    "INSERT INTO batches (batch_key, n_records, n_accepted, report)"
                    " VALUES (?,?,?,?) RETURNING id, (SELECT MAX(id) FROM detections)",
                    (batch_key, report["n_records"], report["accepted"], dumps_json(report)),
                ).fetchall()
                # Ids are given explicitly (the next ones, in record order: the write lock
                # and BEGIN IMMEDIATE make this the only writer) so one executemany inserts
                # them.
                first = 1 if last_id is None else int(last_id) + 1
                ids = tuple(range(first, first + len(detections)))
                c.executemany(
                    "INSERT INTO detections (id, batch_id, t_s, sensor, u_min, v_min, u_max,"
                    " v_max, cls, score, local_id) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                    [
                        (i, batch_id, d.t_s, d.sensor, *d.bbox, d.cls, d.score, d.local_id)
                        for i, d in zip(ids, detections, strict=True)
                    ],
                )
                out.append(StoredBatch(batch_id, ids, report))
            return out

        return self._tx(run)

    def write_derived(
        self,
        fixes: Iterable[tuple[int, float, str, str, str, dict[str, Any]]],
        tracks: Iterable[dict[str, Any]],
        events: Iterable[tuple[str, dict[str, Any]]],
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
            Payloads without ``seq``; each gets the next sequence number.
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
            ``seq``), in order: :func:`published_text` makes the stream's text of it.

        Notes
        -----
        A fix body is encoded once: an event payload that holds one of this call's fix
        bodies as a value (the ``fix`` stream message) reuses that encoding.
        """
        track_list = list(tracks)

        def run(c: sqlite3.Connection) -> list[tuple[int, str]]:
            # id(fix body) -> (the body, kept alive so no other object takes its id; JSON)
            encoded: dict[int, tuple[Any, bytes]] = {}
            fix_rows = []
            for i, t, s, k, st, b in fixes:
                raw = encode_json(b)
                encoded[id(b)] = (b, raw)
                fix_rows.append((i, t, s, k, st, raw.decode()))
            c.executemany(
                "INSERT OR REPLACE INTO fixes (detection_id, t_s, sensor, cls, status, body)"
                " VALUES (?,?,?,?,?,?)",
                fix_rows,
            )
            if replace_tracks:
                self._cuts.clear()  # and nothing of this call is recorded: chains break
                keep = set(keep_track_ids)
                if keep:
                    gone = [(i,) for (i,) in c.execute("SELECT id FROM tracks") if i not in keep]
                    c.executemany("DELETE FROM tracks WHERE id = ?", gone)
                    c.executemany("DELETE FROM track_points WHERE track_id = ?", gone)
                else:
                    c.execute("DELETE FROM tracks")
                    c.execute("DELETE FROM track_points")
            heads, cuts, points = [], [], []
            before = {} if replace_tracks else _track_revs(c, [r["id"] for r in track_list])
            for r in track_list:
                head, texts, start = _split_track_body(r)
                heads.append(
                    (
                        r["id"],
                        r["cls"],
                        r["t_start"],
                        r["t_end"],
                        r["e_min"],
                        r["n_min"],
                        r["e_max"],
                        r["n_max"],
                        dumps_json(r["sensors"]),
                        int(r["live"]),
                        head,
                    )
                )
                cuts.append((r["id"], start))
                points += [(r["id"], start + k, t) for k, t in enumerate(texts)]
            c.executemany(
                "INSERT OR REPLACE INTO tracks (id, cls, t_start, t_end, e_min, n_min, e_max,"
                " n_max, sensors, live, body) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                heads,
            )
            # Points from the first that changed on: dropped, then written again.
            c.executemany("DELETE FROM track_points WHERE track_id = ? AND k >= ?", cuts)
            c.executemany("INSERT INTO track_points (track_id, k, point) VALUES (?,?,?)", points)
            if cuts and not replace_tracks:
                starts: dict[int, int] = {}
                for i, start in cuts:
                    starts[i] = min(start, starts.get(i, start))
                self._cuts.record(before, _track_revs(c, list(starts)), starts)
            for body in activity:
                row = c.execute("SELECT id FROM activity WHERE key = ?", (body["key"],)).fetchone()
                if row is None:
                    cur = c.execute(
                        "INSERT INTO activity (key, kind, t_start, t_end, track_ids, open, body)"
                        " VALUES (?,?,?,?,?,?,'')",
                        (
                            body["key"],
                            body["kind"],
                            body["t_start_s"],
                            body["t_end_s"],
                            dumps_json(body["track_ids"]),
                            int(body["open"]),
                        ),
                    )
                    body["id"] = int(cur.lastrowid or 0)
                else:
                    body["id"] = int(row[0])
                c.execute(
                    "UPDATE activity SET t_start = ?, t_end = ?, track_ids = ?, open = ?,"
                    " body = ? WHERE id = ?",
                    (
                        body["t_start_s"],
                        body["t_end_s"],
                        dumps_json(body["track_ids"]),
                        int(body["open"]),
                        dumps_json(body),
                        body["id"],
                    ),
                )
            rows = [(kind, _encode_reusing(payload, encoded)) for kind, payload in events]
            # AUTOINCREMENT: a sequence number is never reused, even after deletes.
            # The larger of the two, in one statement (both are at least 0).
            first = _next_id(
                c,
                "SELECT MAX(COALESCE((SELECT MAX(seq) FROM events), 0),"
                " COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'events'), 0))",
            )
            seqs = list(range(first, first + len(rows)))
            c.executemany(
                "INSERT INTO events (seq, type, payload) VALUES (?, ?, ?)",
                [(q, kind, text) for q, (kind, text) in zip(seqs, rows, strict=True)],
            )
            return [(q, text) for q, (_, text) in zip(seqs, rows, strict=True)]

        return self._tx(run, sync=False)  # derived rows: see the module docstring

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
        return [_detection_row(r) for r in rows]

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
        return [_detection_row(r) for r in rows]

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
        where, params = _track_where(t_from, t_to, cls, bbox)
        with self._snapshot() as r:  # heads and points from one snapshot
            rows = r.execute(
                f"SELECT id, body FROM tracks{where} ORDER BY id",  # noqa: S608
                params,
            ).fetchall()
            points = _points_of(r, [i for i, _ in rows])
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
        where, params = _track_where(t_from, t_to, cls, bbox)
        with self._snapshot() as r:
            heads = r.execute(
                f"SELECT id, {_REV} FROM tracks{where} ORDER BY id",  # noqa: S608
                params,
            ).fetchall()
            todo = [i for i, rev in heads if known.get(i) != rev]
            cut: dict[int, int] = {}
            if tails:
                for i, rev in heads:
                    held = known.get(i)
                    k0 = None if held in (None, rev) else self._cuts.first_changed(i, held, rev)
                    if k0 is not None:
                        cut[i] = k0
            whole = [i for i in todo if i not in cut]
            texts: dict[int, tuple[int, Any]] = {}
            points = _points_of(r, whole)
            for chunk, marks in _id_chunks(todo):
                for i, rev, body in r.execute(
                    f"SELECT id, {_REV}, body FROM tracks WHERE id IN ({marks})",  # noqa: S608
                    chunk,
                ):
                    if i in cut:
                        tail = [
                            p
                            for (p,) in r.execute(
                                "SELECT point FROM track_points WHERE track_id = ? AND k >= ?"
                                " ORDER BY k",
                                (i, cut[i]),
                            )
                        ]
                        texts[i] = (rev, TrackTail(body, cut[i], tail))
                    else:
                        texts[i] = (rev, track_body_text(body, points[i]))
        return [(i, *texts[i]) if i in texts else (i, rev, None) for i, rev in heads]

    def track(self, track_id: int) -> dict[str, Any] | None:
        """The body of track ``track_id`` (None if there is none), by its primary key."""
        if not -(2**63) <= int(track_id) < 2**63:  # beyond SQLite's integers: no such track
            return None
        with self._snapshot() as r:
            rows = r.execute("SELECT body FROM tracks WHERE id = ?", (int(track_id),)).fetchall()
            points = _points_of(r, [int(track_id)]) if rows else {}
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
        clauses, params = _window_where(t_from, t_to)
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
