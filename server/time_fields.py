"""ISO 8601 UTC beside every ``t_s`` an HTTP answer carries (the stored bodies keep ``t_s``).

Inside, times are UNIX seconds UTC (``t_s``); an answer of ``/api/tracks`` and
``/api/events`` adds the same instants as ISO 8601 with ``Z`` (milliseconds), so a reader
never has to know the epoch. The stored bodies are shared with the server's caches: these
functions copy what they change.
"""

from __future__ import annotations

from typing import Any

from demtrack.core.io.times import format_utc

__all__ = ["event_with_times", "track_with_times"]


def track_with_times(body: dict[str, Any]) -> dict[str, Any]:
    """A copy of a track body whose points carry ``time_utc`` (ISO 8601 of ``t_s``)."""
    points = [{**p, "time_utc": format_utc(p["t_s"])} for p in body["points"]]
    return {**body, "points": points}


def event_with_times(row: dict[str, Any]) -> dict[str, Any]:
    """A copy of an activity body with ``time_utc`` / ``end_time_utc`` (its start, end)."""
    return {
        **row,
        "time_utc": format_utc(row["t_start_s"]),
        "end_time_utc": format_utc(row["t_end_s"]),
    }
