"""Pose telemetry rows: each sensor's poses, written with their ingest batch.

A pose row is ``(sensor, t_s, body)``; the body is the sample's JSON (``t_s``, ``pan_deg``,
``tilt_deg``, and ``hfov_deg``, ``roll_deg``, ``position_enu``, ``platform_ypr_deg`` where
given; degrees, site-frame ENU metres). The rows are inserted in the transaction of the
batch that carried them (:func:`.batches.insert_batch_rows`), so a pose batch is durable
exactly when a detection batch is. Reads go through :class:`~.database.Store`.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from typing import Any

from .codec import dumps_json, loads_json

__all__ = [
    "PoseRow",
    "insert_pose_rows",
    "pose_last_times",
    "pose_rows_in_window",
    "recent_pose_rows",
]

#: ``(sensor, t_s, body)``: one stored pose sample (``t_s``: UNIX s).
PoseRow = tuple[str, float, dict[str, Any]]


def insert_pose_rows(c: sqlite3.Connection, batch_id: int, rows: Sequence[PoseRow]) -> None:
    """Insert ``rows`` for batch ``batch_id`` on ``c`` (inside its transaction)."""
    c.executemany(
        "INSERT INTO poses (sensor, t_s, batch_id, body) VALUES (?,?,?,?)",
        [(s, float(t), batch_id, dumps_json(b)) for s, t, b in rows],
    )


def pose_last_times(c: sqlite3.Connection) -> dict[str, float]:
    """Each sensor's newest stored pose time (s)."""
    rows = c.execute(
        "SELECT sensor, MAX(t_s) FROM poses GROUP BY sensor ORDER BY sensor"
    ).fetchall()
    return {str(s): float(t) for s, t in rows}


def pose_rows_in_window(
    c: sqlite3.Connection,
    sensor: str,
    t_from: float | None,
    t_to: float | None,
    limit: int,
) -> list[dict[str, Any]]:
    """Pose bodies of ``sensor`` with ``t_from <= t_s <= t_to``, in time order."""
    lo = -1e308 if t_from is None else float(t_from)
    hi = 1e308 if t_to is None else float(t_to)
    rows = c.execute(
        "SELECT body FROM poses WHERE sensor = ? AND t_s >= ? AND t_s <= ? ORDER BY t_s LIMIT ?",
        (sensor, lo, hi, int(limit)),
    ).fetchall()
    return [loads_json(r[0]) for r in rows]


def recent_pose_rows(c: sqlite3.Connection, window_s: float) -> dict[str, list[dict[str, Any]]]:
    """Each sensor's pose bodies at most ``window_s`` behind its newest, in time order."""
    out: dict[str, list[dict[str, Any]]] = {}
    for sensor, newest in pose_last_times(c).items():
        out[sensor] = pose_rows_in_window(c, sensor, newest - float(window_s), None, 2**62)
    return out
