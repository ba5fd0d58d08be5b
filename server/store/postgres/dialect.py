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

from ..codec import encode_json
from ..dialect import Dialect

__all__ = ["BATCH_LOCK", "EVENT_CHANNEL", "EVENT_LOCK", "POSTGRES", "PostgresDialect"]

#: Advisory lock keys (transaction level): ingest batches, and the event log's numbering.
BATCH_LOCK = 0x64656D_0002
EVENT_LOCK = 0x64656D_0003
#: The channel every event-writing transaction notifies (payload: the newest ``seq``).
EVENT_CHANNEL = "demtrack_events"

_HEAD_COLUMNS = (
    "id", "cls", "t_start", "t_end", "e_min", "n_min", "e_max", "n_max", "sensors", "live", "body"
)  # fmt: skip
_COLUMNS = ", ".join(_HEAD_COLUMNS)
# The rows as one JSON array; each element also carries its ``start`` (not a column).
_UPSERT_TRACKS = (
    f"INSERT INTO tracks AS t ({_COLUMNS}, geom)"  # noqa: S608 (fixed text)
    f" SELECT {', '.join('r.' + k for k in _HEAD_COLUMNS)},"
    " demtrack_track_line((SELECT o.geom FROM tracks AS o WHERE o.id = r.id), r.id,"
    " (j ->> 'start')::int)"
    " FROM json_array_elements(%s::json) AS j, json_populate_record(NULL::tracks, j) AS r"
    " ON CONFLICT (id) DO UPDATE SET "
    + ", ".join(f"{k} = EXCLUDED.{k}" for k in (*_HEAD_COLUMNS[1:], "geom"))
)


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
        """Upsert the heads in one statement, each line the old one to its start + points.

        A track given twice keeps its last head and its smallest start (the points are
        stored already: the line up to the smaller start is the old one either way).
        """
        rows: dict[int, dict[str, Any]] = {}
        for h, start in zip(heads, starts, strict=True):
            row = dict(zip(_HEAD_COLUMNS, h, strict=True))
            row["start"] = min(start, rows[h[0]]["start"]) if h[0] in rows else start
            rows[h[0]] = row
        if rows:
            c.raw.execute(_UPSERT_TRACKS, (encode_json(list(rows.values())).decode(),))

    def insert_id(self, c: Any, sql: str, params: Sequence[Any]) -> int:
        """Run the ``INSERT`` ``sql`` (one row) ``RETURNING id``; the new row's id."""
        return int(c.execute(sql + " RETURNING id", params).fetchone()[0])

    def append_events(self, c: Any, rows: Sequence[tuple[str, str]]) -> list[int]:
        """Append events under :data:`EVENT_LOCK`, then notify :data:`EVENT_CHANNEL`."""
        if not rows:
            return []
        # The lock first, in a statement of its own: the next statement's snapshot then
        # sees every event committed before the lock was granted.
        c.execute("SELECT pg_advisory_xact_lock(?)", (EVENT_LOCK,))
        # Numbers, rows and the notification in one statement (one round trip).
        got = c.execute(
            "WITH top AS (SELECT COALESCE(MAX(seq), 0) AS m FROM events),"
            " ins AS (INSERT INTO events (seq, type, payload)"
            " SELECT top.m + u.k, u.type, u.payload FROM top,"
            " unnest(?::text[], ?::text[]) WITH ORDINALITY AS u(type, payload, k)"
            " RETURNING seq)"
            " SELECT top.m, pg_notify(?, (top.m + ?)::text) FROM top",
            ([k for k, _ in rows], [t for _, t in rows], EVENT_CHANNEL, len(rows)),
        ).fetchone()
        first = int(got[0]) + 1
        return list(range(first, first + len(rows)))


#: The PostgreSQL dialect.
POSTGRES = PostgresDialect()
