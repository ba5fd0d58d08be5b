"""PostgreSQL's statements where they differ from SQLite's (:mod:`demtrack.server.store.dialect`).

Upserts are ``ON CONFLICT DO UPDATE``; a track head's LineString is made by the database
from its stored points (``demtrack_track_line``: the old line up to the first changed
point, then the new points). The event log is numbered under an advisory lock held to the
end of the transaction, so sequence numbers become visible in order across processes, and
every transaction that appends events ends with ``pg_notify('demtrack_events', newest
seq)`` (delivered when it commits).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..dialect import Dialect

__all__ = ["BATCH_LOCK", "EVENT_CHANNEL", "EVENT_LOCK", "POSTGRES", "PostgresDialect"]

#: Advisory lock keys (transaction level): ingest batches, and the event log's numbering.
BATCH_LOCK = 0x64656D_0002
EVENT_LOCK = 0x64656D_0003
#: The channel every event-writing transaction notifies (payload: the newest ``seq``).
EVENT_CHANNEL = "demtrack_events"

_TRACK_COLUMNS = ("cls", "t_start", "t_end", "e_min", "n_min", "e_max", "n_max", "sensors")
_SET_TRACK = ", ".join(f"{k} = EXCLUDED.{k}" for k in (*_TRACK_COLUMNS, "live", "body"))


class PostgresDialect(Dialect):
    """PostgreSQL's statements (see the module docstring)."""

    kind = "postgres"

    upsert_fix = (
        "INSERT INTO fixes (detection_id, t_s, sensor, cls, status, body) VALUES (?,?,?,?,?,?)"
        " ON CONFLICT (detection_id) DO UPDATE SET t_s = EXCLUDED.t_s,"
        " sensor = EXCLUDED.sensor, cls = EXCLUDED.cls, status = EXCLUDED.status,"
        " body = EXCLUDED.body"
    )

    first_track_id = "(track_ids::jsonb ->> 0)"

    def write_track_heads(
        self, c: Any, heads: Sequence[tuple[Any, ...]], starts: Sequence[int]
    ) -> None:
        """Upsert the heads; each line is the old one up to ``start``, then the points."""
        c.executemany(
            "INSERT INTO tracks AS t (id, cls, t_start, t_end, e_min, n_min, e_max, n_max,"
            " sensors, live, body, geom) VALUES (?,?,?,?,?,?,?,?,?,?,?,"
            " demtrack_track_line(NULL, ?, 0))"
            f" ON CONFLICT (id) DO UPDATE SET {_SET_TRACK},"
            " geom = demtrack_track_line(t.geom, t.id, ?)",
            [(*h, h[0], s) for h, s in zip(heads, starts, strict=True)],
        )

    def insert_id(self, c: Any, sql: str, params: Sequence[Any]) -> int:
        """Run the ``INSERT`` ``sql`` (one row) ``RETURNING id``; the new row's id."""
        return int(c.execute(sql + " RETURNING id", params).fetchone()[0])

    def append_events(self, c: Any, rows: Sequence[tuple[str, str]]) -> list[int]:
        """Append events under :data:`EVENT_LOCK`, then notify :data:`EVENT_CHANNEL`."""
        c.execute("SELECT pg_advisory_xact_lock(?)", (EVENT_LOCK,))
        row = c.execute("SELECT COALESCE(MAX(seq), 0) FROM events").fetchone()
        first = int(row[0]) + 1
        seqs = list(range(first, first + len(rows)))
        c.executemany(
            "INSERT INTO events (seq, type, payload) VALUES (?, ?, ?)",
            [(q, kind, text) for q, (kind, text) in zip(seqs, rows, strict=True)],
        )
        if seqs:
            c.execute("SELECT pg_notify(?, ?)", (EVENT_CHANNEL, str(seqs[-1])))
        return seqs


#: The PostgreSQL dialect.
POSTGRES = PostgresDialect()
