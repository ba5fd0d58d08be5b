"""``/api/events``: detected events (activity, hand-off predictions, track life cycle)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, HTTPException, Query
from pydantic import BaseModel, ConfigDict

from ..messages import EventBody
from ..state import StateDep

__all__ = ["EVENT_KINDS", "EventsOut", "router"]

router = APIRouter(prefix="/api/events", tags=["events"])

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


_KIND = Query(None, description="only these kinds (repeat the parameter)")


class EventsOut(BaseModel):
    """Events overlapping the window, by start time."""

    model_config = ConfigDict(extra="forbid")

    events: list[EventBody]


@router.get("", response_model=EventsOut, summary="Detected events")
def list_events(
    state: StateDep,
    t_from: float | None = Query(None, description="window start (s)", allow_inf_nan=False),
    t_to: float | None = Query(None, description="window end (s)", allow_inf_nan=False),
    kind: list[Kind] | None = _KIND,
    track: int | None = Query(None, ge=0, description="only events involving this track"),
    open_only: bool = Query(False, alias="open", description="only episodes still going on"),
    limit: int = Query(1000, ge=1, le=10_000),
) -> dict[str, Any]:
    """Stored events whose ``[t_start_s, t_end_s]`` overlaps the window.

    Loitering, rendezvous and convoy episodes, zone entries and exits, hand-off
    predictions (``t_end_s`` = predicted exit time) and tracks confirmed / ended.
    """
    if t_from is not None and t_to is not None and t_from > t_to:
        raise HTTPException(422, f"t_from ({t_from}) is after t_to ({t_to})")
    rows = state.store.activity(
        t_from=t_from,
        t_to=t_to,
        kinds=kind,
        open_only=open_only,
        limit=limit if track is None else 100_000,
    )
    if track is not None:
        rows = [r for r in rows if track in r["track_ids"]][:limit]
    return {"events": rows}
