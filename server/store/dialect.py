"""What differs between the store's two SQL dialects: the SQLite one, here.

The store's SQL is written once, with ``?`` placeholders, wherever SQLite and PostgreSQL
agree (every read, the batch inserts, the track-point writes). The few statements where
they do not (an upsert, numbering the event log, a JSON path, a returned row id) are the
methods of a :class:`Dialect`; :mod:`.postgres.dialect` gives PostgreSQL's. The writers
(:mod:`.derived`, :mod:`.markers`) take the store's dialect and call these.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ["SQLITE", "Dialect"]


class Dialect:
    """SQLite's statements (the base class; PostgreSQL's overrides them).

    ``c`` is the store's write connection inside its transaction: a
    :class:`sqlite3.Connection` here, a ``?``-placeholder wrapper of a psycopg
    connection for PostgreSQL (:class:`~.postgres.connection.QmarkConnection`).
    """

    #: ``store.kind``: which database.
    kind = "sqlite"

    def write_fixes(
        self, c: Any, rows: Sequence[tuple[Any, ...]], bodies: Sequence[dict[str, Any]]
    ) -> None:
        """Insert fix rows, each replacing the one of its detection.

        ``rows``: ``(detection_id, t_s, sensor, cls, status, body text)``; ``bodies[k]``:
        row ``k``'s body as a dict.
        """
        c.executemany(
            "INSERT OR REPLACE INTO fixes (detection_id, t_s, sensor, cls, status, body)"
            " VALUES (?,?,?,?,?,?)",
            rows,
        )

    def write_points(self, c: Any, rows: Sequence[tuple[int, int, str]]) -> None:
        """Insert track points ``(track_id, k, point text)`` (none of them is stored)."""
        c.executemany("INSERT INTO track_points (track_id, k, point) VALUES (?,?,?)", rows)

    #: The first track id of an activity row's ``track_ids`` (a JSON list of ints).
    first_track_id = "json_extract(track_ids, '$[0]')"

    def write_track_heads(
        self, c: Any, heads: Sequence[tuple[Any, ...]], starts: Sequence[int]
    ) -> None:
        """Insert or replace track heads, whose points are written already.

        ``heads``: ``(id, cls, t_start, t_end, e_min, n_min, e_max, n_max, sensors, live,
        body)`` rows; ``starts[k]``: the first point index head ``k``'s write changed.
        """
        c.executemany(
            "INSERT OR REPLACE INTO tracks (id, cls, t_start, t_end, e_min, n_min, e_max,"
            " n_max, sensors, live, body) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            heads,
        )

    def insert_id(self, c: Any, sql: str, params: Sequence[Any]) -> int:
        """Run the ``INSERT`` ``sql`` (one row); the new row's id."""
        return int(c.execute(sql, params).lastrowid or 0)

    def append_events(self, c: Any, rows: Sequence[tuple[str, str]]) -> list[int]:
        """Append ``(type, payload text)`` rows to the event log; their sequence numbers.

        A sequence number is never reused, even after deletes (AUTOINCREMENT's
        ``sqlite_sequence`` remembers the highest ever given).
        """
        row = c.execute(
            "SELECT MAX(COALESCE((SELECT MAX(seq) FROM events), 0),"
            " COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'events'), 0))"
        ).fetchone()
        first = int(row[0] or 0) + 1
        seqs = list(range(first, first + len(rows)))
        c.executemany(
            "INSERT INTO events (seq, type, payload) VALUES (?, ?, ?)",
            [(q, kind, text) for q, (kind, text) in zip(seqs, rows, strict=True)],
        )
        return seqs


#: The SQLite dialect (the store's default).
SQLITE = Dialect()
