"""Derived rows: fixes, tracks (heads and point texts), activity and the event log.

:func:`write_derived_rows` runs inside one store write transaction, committed without a
WAL sync of its own (see :mod:`demtrack.server.store`). A fix body is encoded once: an
event payload holding one of the call's fix bodies (the ``fix`` stream message) reuses
that text (:func:`~demtrack.server.store.codec.encode_reusing`), so the stream sends
exactly what the fixes table holds.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from ..track_history import PointCuts
from .codec import dumps_json, encode_json, encode_reusing, split_track_body
from .dialect import SQLITE, Dialect
from .queries import track_revs

__all__ = ["FixRow", "write_derived_rows"]

#: ``(detection_id, t_s, sensor, cls, status, body)`` of the fixes table.
FixRow = tuple[int, float, str, str, str, dict[str, Any]]


def write_derived_rows(
    c: Any,
    history: PointCuts,
    fixes: Iterable[FixRow],
    tracks: Sequence[dict[str, Any]],
    events: Iterable[tuple[str, Any]],
    *,
    replace_tracks: bool,
    keep_track_ids: Iterable[int],
    activity: Iterable[dict[str, Any]],
    dialect: Dialect = SQLITE,
) -> list[tuple[int, str]]:
    """Write derived rows on ``c`` (inside its transaction); each event's ``(seq, text)``.

    See :meth:`demtrack.server.store.database.Store.write_derived` for the arguments;
    ``history`` records what each track write rewrote (for readers of tails), ``dialect``
    the SQL where the databases differ (:mod:`.dialect`).
    """
    # id(fix body) -> (the body, kept alive so no other object takes its id; JSON)
    encoded: dict[int, tuple[Any, bytes]] = {}
    fix_rows, fix_bodies = [], []
    for i, t, s, k, st, b in fixes:
        raw = encode_json(b)
        encoded[id(b)] = (b, raw)
        fix_rows.append((i, t, s, k, st, raw.decode()))
        fix_bodies.append(b)
    dialect.write_fixes(c, fix_rows, fix_bodies)
    if replace_tracks:
        history.clear()  # and nothing of this call is recorded: chains break
        keep = set(keep_track_ids)
        if keep:
            gone = [(i,) for (i,) in c.execute("SELECT id FROM tracks") if i not in keep]
            c.executemany("DELETE FROM tracks WHERE id = ?", gone)
            c.executemany("DELETE FROM track_points WHERE track_id = ?", gone)
        else:
            c.execute("DELETE FROM tracks")
            c.execute("DELETE FROM track_points")
    heads, cuts, points = [], [], []
    before = {} if replace_tracks else track_revs(c, [r["id"] for r in tracks])
    for r in tracks:
        head, texts, start = split_track_body(r)
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
    # Points from the first that changed on: dropped, then written again; then the heads
    # (PostgreSQL's track line is made from the stored points: they go first).
    c.executemany("DELETE FROM track_points WHERE track_id = ? AND k >= ?", cuts)
    dialect.write_points(c, points)
    dialect.write_track_heads(c, heads, [start for _, start in cuts])
    if cuts and not replace_tracks:
        starts: dict[int, int] = {}
        for i, start in cuts:
            starts[i] = min(start, starts.get(i, start))
        history.record(before, track_revs(c, list(starts)), starts)
    for body in activity:
        row = c.execute("SELECT id FROM activity WHERE key = ?", (body["key"],)).fetchone()
        if row is None:
            # The next id, given explicitly (SQLite's own choice): the same on both.
            ((body["id"],),) = c.execute(
                "INSERT INTO activity (id, key, kind, t_start, t_end, track_ids, open, body)"
                " VALUES ((SELECT COALESCE(MAX(id), 0) + 1 FROM activity),?,?,?,?,?,?,'{}')"
                " RETURNING id",
                (
                    body["key"],
                    body["kind"],
                    body["t_start_s"],
                    body["t_end_s"],
                    dumps_json(body["track_ids"]),
                    int(body["open"]),
                ),
            ).fetchall()
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
    rows = [(kind, encode_reusing(payload, encoded)) for kind, payload in events]
    seqs = dialect.append_events(c, rows) if rows else []
    return [(q, text) for q, (_, text) in zip(seqs, rows, strict=True)]
