"""``/api/events``: detected events (activity, hand-off predictions, track life cycle)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict, Field

from .. import listing
from ..listing import EVENT_KINDS
from ..messages import EventBody
from ..time_fields import event_with_times
from .deps import StateDep, TimeFrom, TimeTo

__all__ = ["EVENT_KINDS", "EventsOut", "router"]

router = APIRouter(prefix="/api/events", tags=["events"])

Kind = Literal[
    "loitering",
    "rendezvous",
    "convoy",
    "zone-enter",
    "zone-leave",
    "handoff",
    "track_confirmed",
    "track_ended",
]


_KIND = Query(
    None,
    description="only these kinds (repeat the parameter); default every kind but handoff",
)
_SENSOR = Query(None, description="only events one of these sensors saw (repeat)")


class EventOut(EventBody):
    """A stored event with its start and end as ISO 8601 UTC beside the UNIX seconds."""

    time_utc: str = Field(description="t_start_s as ISO 8601 UTC with Z")
    end_time_utc: str = Field(description="t_end_s as ISO 8601 UTC with Z")


class EventsOut(BaseModel):
    """Events overlapping the window, by start time."""

    model_config = ConfigDict(extra="forbid")

    events: list[EventOut]
    next_offset: int | None = Field(
        None, description="the offset of the next page; null when this is the last"
    )


@router.get("", response_model=EventsOut, summary="Detected events")
def list_events(
    state: StateDep,
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    kind: list[Kind] | None = _KIND,
    track: int | None = Query(None, ge=0, description="only events involving this track"),
    open_only: bool = Query(False, alias="open", description="only episodes still going on"),
    sensor: list[str] | None = _SENSOR,
    limit: int = Query(1000, ge=1, le=10_000),
    offset: int = Query(0, ge=0, le=10_000_000, description="rows to skip (paging)"),
) -> dict[str, Any]:
    """Stored events whose ``[t_start_s, t_end_s]`` overlaps the window.

    What happened: loitering, rendezvous and convoy episodes, zone entries and exits,
    tracks confirmed / ended. Hand-off predictions (``kind=handoff``: one per track, the
    newest, ``t_end_s`` = predicted exit time) only when asked for. Pages of ``limit``
    rows: ask again with ``offset=next_offset``.
    """
    rows, nxt = listing.list_events(
        state, t_from, t_to, kind, track, open_only, limit, sensor, offset
    )
    return {"events": [event_with_times(r) for r in rows], "next_offset": nxt}
