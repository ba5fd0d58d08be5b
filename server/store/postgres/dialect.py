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

from ..codec import encode_json, loads_json
from ..dialect import Dialect

__all__ = ["BATCH_LOCK", "EVENT_CHANNEL", "EVENT_LOCK", "POSTGRES", "PostgresDialect"]

#: Advisory lock keys (transaction level): ingest batches, and the event log's numbering.
BATCH_LOCK = 0x64656D_0002
EVENT_LOCK = 0x64656D_0003
#: The channel every event-writing transaction notifies (payload: the newest ``seq``).
EVENT_CHANNEL = "demtrack_events"

# Each column a binary array parameter (no text escaping in Python; floats exact).
_UPSERT_FIXES = (
    "INSERT INTO fixes (detection_id, t_s, sensor, cls, status, body, geom)"
    " SELECT i, t, s, k, st, b, ST_MakePoint(e, n) FROM unnest(%b::bigint[], %b::float8[],"
    " %b::text[], %b::text[], %b::text[], %b::text[], %b::float8[], %b::float8[])"
    " AS u(i, t, s, k, st, b, e, n)"
    " ON CONFLICT (detection_id) DO UPDATE SET t_s = EXCLUDED.t_s, sensor = EXCLUDED.sensor,"
    " cls = EXCLUDED.cls, status = EXCLUDED.status, body = EXCLUDED.body, geom = EXCLUDED.geom"
)


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None


def _first_hit(body: dict[str, Any]) -> tuple[float | None, float | None]:
    """A fix body's first hit ``(e_m, n_m)``, or ``(None, None)`` (no Point)."""
    hits = body.get("hits") if isinstance(body, dict) else None
    if not hits or not isinstance(hits[0], dict):
        return None, None
    return _number(hits[0].get("e_m")), _number(hits[0].get("n_m"))


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

    def write_fixes(
        self, c: Any, rows: Sequence[tuple[Any, ...]], bodies: Sequence[dict[str, Any]]
    ) -> None:
        """Upsert the fix rows in one statement, with each one's Point (its first hit).

        A detection given twice keeps its last row (what row-by-row upserts leave).
        """
        last: dict[int, int] = {int(r[0]): k for k, r in enumerate(rows)}
        if not last:
            return
        keep = sorted(last.values())
        cols: list[list[Any]] = [[rows[k][j] for k in keep] for j in range(6)]
        cols[0] = [int(v) for v in cols[0]]
        cols[1] = [float(v) for v in cols[1]]
        xy = [_first_hit(bodies[k]) for k in keep]
        c.raw.execute(_UPSERT_FIXES, (*cols, [p[0] for p in xy], [p[1] for p in xy]))

    def write_points(self, c: Any, rows: Sequence[tuple[int, int, str]]) -> None:
        """Insert track points in one statement, with their Points (``e_m``, ``n_m``)."""
        if not rows:
            return
        xy = [loads_json(t) for _, _, t in rows]
        c.raw.execute(
            "INSERT INTO track_points (track_id, k, point, geom)"
            " SELECT i, k, p, ST_MakePoint(e, n)"
            " FROM unnest(%b::bigint[], %b::integer[], %b::text[], %b::float8[], %b::float8[])"
            " AS u(i, k, p, e, n)",
            (
                [int(r[0]) for r in rows],
                [int(r[1]) for r in rows],
                [r[2] for r in rows],
                [_number(d.get("e_m")) for d in xy],
                [_number(d.get("n_m")) for d in xy],
            ),
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
        # Types and payloads as binary text arrays (a text-format array would be escaped
        # element by element in Python: 0.1 s for a 500-detection batch).
        got = c.raw.execute(
            "WITH top AS (SELECT COALESCE(MAX(seq), 0) AS m FROM events),"
            " ins AS (INSERT INTO events (seq, type, payload)"
            " SELECT top.m + u.k, u.type, u.payload FROM top,"
            " unnest(%b::text[], %b::text[]) WITH ORDINALITY AS u(type, payload, k)"
            " RETURNING seq)"
            " SELECT top.m, pg_notify(%s, (top.m + %s)::text) FROM top",
            ([k for k, _ in rows], [t for _, t in rows], EVENT_CHANNEL, len(rows)),
        ).fetchone()
        first = int(got[0]) + 1
        return list(range(first, first + len(rows)))


#: The PostgreSQL dialect.
POSTGRES = PostgresDialect()
