"""The store's read side, shared by both databases: every query the server makes.

:class:`StoreReads` is the base of :class:`~.database.SqliteStore` and
:class:`~.postgres.database.PostgresStore`: the SQL of every read is the same in both
(``?`` placeholders; PostgreSQL's connection wrapper turns them into its own), so an API
answer is the same text from either. A subclass gives the read connection
(:meth:`StoreReads._rows`, :meth:`StoreReads._snapshot`), its :class:`~.dialect.Dialect`
and the write history of its track rows (``_cuts``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from typing import Any

from demtrack.core.tracking.types import Detection

from ..track_history import PointCuts
from .codec import loads_json, track_body_text
from .dialect import Dialect
from .poses import pose_last_times, pose_rows_in_window, recent_pose_rows
from .queries import detection_row, points_of, read_track_rows, track_where, window_where
from .schema import COUNTED_TABLES

__all__ = ["StoreReads"]


class StoreReads:
    """The read methods of a store (see the module docstring)."""

    dialect: Dialect
    _cuts: PointCuts

    @property
    def kind(self) -> str:
        """``"sqlite"`` or ``"postgres"``: which database this store is."""
        return self.dialect.kind

    def _snapshot(self) -> contextlib.AbstractContextManager[Any]:
        """The read connection inside one read transaction: its reads see one snapshot."""
        raise NotImplementedError

    def _rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        """The rows of one read statement (``?`` placeholders)."""
        raise NotImplementedError

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
        """Latest accepted detection time per sensor (s), by sensor name.

        Sorted here, not by SQL: the databases' text orders may differ (collations).
        """
        return {
            s: float(t)
            for s, t in self._rows(
                "SELECT sensor, MAX(t_s) FROM detections GROUP BY sensor ORDER BY sensor"
            )
        }

    def sensor_counts(self) -> dict[str, int]:
        """Accepted detections per sensor, by sensor name."""
        return {
            s: int(n)
            for s, n in self._rows(
                "SELECT sensor, COUNT(*) FROM detections GROUP BY sensor ORDER BY sensor"
            )
        }

    def pose_last_times(self) -> dict[str, float]:
        """Each sensor's newest stored pose time (s)."""
        with self._snapshot() as r:
            return pose_last_times(r)

    def poses(
        self,
        sensor: str,
        t_from: float | None = None,
        t_to: float | None = None,
        limit: int = 1_000_000,
    ) -> list[dict[str, Any]]:
        """Stored pose bodies of ``sensor`` in ``[t_from, t_to]`` (s), in time order."""
        with self._snapshot() as r:
            return pose_rows_in_window(r, sensor, t_from, t_to, limit)

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
            f" WHERE kind = ? GROUP BY {self.dialect.first_track_id}) ORDER BY id",  # noqa: S608
            (kind,),
        )
        return [loads_json(r[0]) for r in rows]
