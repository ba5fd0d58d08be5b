"""Read-side SQL of the store: selections, track bodies by version, detection rows.

Functions of an open connection (the caller holds its lock and, where reads must agree,
one read transaction: :meth:`demtrack.server.store.database.Store._snapshot`). Track
bodies are joined from their stored head and point texts
(:func:`~demtrack.server.store.codec.track_body_text`).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from demtrack.core.tracking.types import Detection

from ..track_history import PointCuts
from .codec import track_body_text

__all__ = [
    "REV",
    "TrackTail",
    "detection_row",
    "id_chunks",
    "points_of",
    "read_track_rows",
    "track_revs",
    "track_where",
    "window_where",
]

#: A track row's version (see migration 3); 0 for a row written before it.
REV = "COALESCE((SELECT rev FROM track_rev WHERE track_rev.id = tracks.id), 0)"


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


def id_chunks(ids: Sequence[int], size: int = 500) -> Iterator[tuple[list[int], str]]:
    """``ids`` in chunks, each with its ``?,?,...`` placeholders for an ``IN (...)``."""
    for k in range(0, len(ids), size):
        chunk = list(ids[k : k + size])
        yield chunk, ",".join("?" * len(chunk))


def track_revs(c: sqlite3.Connection, ids: Sequence[int]) -> dict[int, int]:
    """The current ``track_rev`` of tracks ``ids`` (those that have one)."""
    out: dict[int, int] = {}
    for chunk, marks in id_chunks(ids):
        out.update(c.execute(f"SELECT id, rev FROM track_rev WHERE id IN ({marks})", chunk))  # noqa: S608
    return out


def points_of(c: sqlite3.Connection, ids: Sequence[int]) -> dict[int, list[str]]:
    """The stored point texts of tracks ``ids``, in order (an empty list for none)."""
    out: dict[int, list[str]] = {i: [] for i in ids}
    for chunk, marks in id_chunks(ids):
        for tid, point in c.execute(
            f"SELECT track_id, point FROM track_points WHERE track_id IN ({marks})"  # noqa: S608
            " ORDER BY track_id, k",
            chunk,
        ):
            out[tid].append(point)
    return out


def window_where(t_from: float | None, t_to: float | None) -> tuple[list[str], list[float | str]]:
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


def track_where(
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    bbox: tuple[float, float, float, float] | None,
) -> tuple[str, list[float | str]]:
    """The ``WHERE`` clause and parameters of a track selection (time, class, box overlap)."""
    clauses, params = window_where(t_from, t_to)
    if cls is not None:
        clauses.append("cls = ?")
        params.append(cls)
    if bbox is not None:
        clauses += ["e_max >= ?", "n_max >= ?", "e_min <= ?", "n_min <= ?"]
        params += list(bbox)
    return (" WHERE " + " AND ".join(clauses) if clauses else ""), params


def detection_row(r: Sequence[Any]) -> tuple[int, Detection]:
    """``(id, Detection)`` of a detections row read in its column order.

    Columns: ``id, t_s, sensor, u_min, v_min, u_max, v_max, cls, score, local_id``.
    """
    return r[0], Detection(r[1], r[2], (r[3], r[4], r[5], r[6]), r[7], r[8], r[9])


def read_track_rows(
    r: sqlite3.Connection,
    known: Mapping[int, int],
    where: str,
    params: Sequence[Any],
    cuts: PointCuts | None,
) -> list[tuple[int, int, Any]]:
    """``(id, rev, body text or TrackTail or None)`` of the selected tracks, by id.

    See :meth:`demtrack.server.store.database.Store.track_rows`; ``cuts``: the store's
    write history when tails are wanted, else None. ``r`` is inside one read transaction.
    """
    heads = r.execute(
        f"SELECT id, {REV} FROM tracks{where} ORDER BY id",  # noqa: S608
        params,
    ).fetchall()
    todo = [i for i, rev in heads if known.get(i) != rev]
    cut: dict[int, int] = {}
    if cuts is not None:
        for i, rev in heads:
            held = known.get(i)
            k0 = None if held in (None, rev) else cuts.first_changed(i, held, rev)
            if k0 is not None:
                cut[i] = k0
    whole = [i for i in todo if i not in cut]
    texts: dict[int, tuple[int, Any]] = {}
    points = points_of(r, whole)
    for chunk, marks in id_chunks(todo):
        for i, rev, body in r.execute(
            f"SELECT id, {REV}, body FROM tracks WHERE id IN ({marks})",  # noqa: S608
            chunk,
        ):
            if i in cut:
                tail = [
                    p
                    for (p,) in r.execute(
                        "SELECT point FROM track_points WHERE track_id = ? AND k >= ? ORDER BY k",
                        (i, cut[i]),
                    )
                ]
                texts[i] = (rev, TrackTail(body, cut[i], tail))
            else:
                texts[i] = (rev, track_body_text(body, points[i]))
    return [(i, *texts[i]) if i in texts else (i, rev, None) for i, rev in heads]
