"""Stored detections and events listed by window and filter, for the read endpoints.

Times are session seconds; windows are inclusive. Bad filters raise
:class:`~demtrack.core.errors.QueryError` (HTTP 422) and an unknown sensor
:class:`~demtrack.core.errors.NotFoundError` (404).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from demtrack.core.errors import NotFoundError, QueryError
from demtrack.core.io.times import format_utc
from demtrack.core.tracking.types import Detection

from .state import ConsoleState
from .track_query import check_window

__all__ = ["EVENT_KINDS", "HAPPENED_KINDS", "detection_rows", "list_detections", "list_events"]

#: Kinds of stored events.
EVENT_KINDS = (
    "loitering",
    "rendezvous",
    "convoy",
    "zone-enter",
    "zone-leave",
    "handoff",
    "track_confirmed",
    "track_ended",
)


def list_detections(
    state: ConsoleState,
    after_id: int,
    limit: int,
    t_from: float | None,
    t_to: float | None,
    sensor: list[str] | None,
) -> list[tuple[int, Detection]]:
    """Stored ``(id, detection)`` pairs, in id order, or by time with a window or sensors.

    Without a window or ``sensor`` filter: arrival (id) order, for paging with
    ``after_id``. With one: the detections of those sensors (default all) in
    ``[t_from, t_to]`` (open ends unbounded), by time then id; ``after_id`` still applies.
    """
    if t_from is not None and t_to is not None and t_to < t_from:
        raise QueryError(f"t_to ({t_to}) is before t_from ({t_from})")
    if t_from is None and t_to is None and not sensor:
        rows: list[tuple[int, Detection]] = state.store.detections(after_id, limit)
        return rows
    known = state.site.sensors
    unknown = [s for s in sensor or [] if s not in known]
    if unknown:
        raise NotFoundError(f"unknown sensor {unknown[0]!r}")
    lo = -math.inf if t_from is None else t_from
    hi = math.inf if t_to is None else t_to
    sensors = sorted(set(sensor or known))
    rows = state.store.detections_in_window(sensors, lo, hi, after_id, limit)
    return rows


def detection_rows(rows: list[tuple[int, Detection]]) -> list[dict[str, Any]]:
    """``StoredDetectionOut``'s JSON of each pair (``cls`` under its alias ``class``)."""
    return [
        {
            "id": i,
            "t": d.t_s,
            "time_utc": format_utc(d.t_s),
            "sensor": d.sensor,
            "bbox": d.bbox,
            "class": d.cls,
            "score": d.score,
            "local_id": d.local_id,
        }
        for i, d in rows
    ]


#: What happened: every stored kind but the hand-off prediction (a per-track annotation,
#: listed only when asked for with ``kind=handoff``).
HAPPENED_KINDS = tuple(k for k in EVENT_KINDS if k != "handoff")


def list_events(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    kinds: Sequence[str] | None,
    track: int | None,
    open_only: bool,
    limit: int,
    sensors: Sequence[str] | None = None,
    offset: int = 0,
) -> tuple[list[dict[str, Any]], int | None]:
    """Stored events whose ``[t_start_s, t_end_s]`` overlaps the window, by start time.

    ``kinds``: only these (default :data:`HAPPENED_KINDS`: hand-off predictions only when
    asked for); ``track``: only events involving it; ``sensors``: only events one of them
    saw; ``open_only``: only episodes still going on; ``offset`` rows skipped, then at most
    ``limit``. Returns the rows and the ``offset`` of the next page (None: no more).
    """
    check_window(t_from, t_to)
    if sensors:
        known = state.site.sensors
        unknown = [s for s in sensors if s not in known]
        if unknown:
            raise NotFoundError(f"unknown sensor {unknown[0]!r}")
    filtered = track is not None or bool(sensors)
    rows: list[dict[str, Any]] = state.store.activity(
        t_from=t_from,
        t_to=t_to,
        kinds=list(kinds) if kinds else list(HAPPENED_KINDS),
        open_only=open_only,
        limit=offset + limit + 1 if not filtered else 1_000_000,
    )
    if track is not None:
        rows = [r for r in rows if track in r["track_ids"]]
    if sensors:
        wanted = set(sensors)
        rows = [r for r in rows if wanted.intersection(r.get("sensors") or ())]
    page = rows[offset : offset + limit]
    more = len(rows) > offset + limit
    return page, (offset + limit if more else None)
