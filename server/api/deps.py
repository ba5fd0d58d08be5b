"""Dependency aliases the routers share: the server state, the auth checks, common queries.

Each alias is an ``Annotated`` type, so an endpoint says what it needs in its signature
(``state: StateDep``, ``t_from: TimeFrom = None``) and the OpenAPI description of a
parameter is written once.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import Depends, Query, Request
from pydantic import BeforeValidator, ValidationInfo, WithJsonSchema

from demtrack.core.io.times import parse_time_value

from ..security import require_operator, require_reader
from ..state import ConsoleState

__all__ = [
    "OPERATOR",
    "READER",
    "SQLITE_INT_MAX",
    "BBoxQuery",
    "StateDep",
    "TimeFrom",
    "TimeQuery",
    "TimeTo",
    "TrackClass",
    "TrackSensor",
    "get_state",
]


async def get_state(request: Request) -> ConsoleState:
    """The app's :class:`ConsoleState` (built in the lifespan).

    ``async``: a plain ``def`` dependency would take a worker thread for each request.
    """
    state: ConsoleState = request.app.state.console
    return state


#: The running server's state.
StateDep = Annotated[ConsoleState, Depends(get_state)]

#: ``dependencies=`` of the read-only endpoints (open with ``open_reads``).
READER = (Depends(require_reader),)
#: ``dependencies=`` of the write endpoints (always the operator token).
OPERATOR = (Depends(require_operator),)

#: The largest integer SQLite stores: every id a query takes is bounded by it (a larger
#: one raised ``OverflowError`` in the driver, an HTTP 500).
SQLITE_INT_MAX = 2**63 - 1


def _time_query(value: object, info: ValidationInfo) -> object:
    """A time parameter as UNIX seconds: a number, or ISO 8601 with a zone (422 without)."""
    if value is None:
        return None
    return parse_time_value(value, info.field_name or "time")


#: A time query parameter's OpenAPI schema: UNIX seconds or an ISO 8601 string with a zone.
_TIME_SCHEMA = WithJsonSchema(
    {"anyOf": [{"type": "number"}, {"type": "string", "format": "date-time"}, {"type": "null"}]}
)
#: A time query parameter: UNIX seconds UTC, or ISO 8601 with a zone (``...Z``, ``+01:00``).
TimeQuery = Annotated[float | None, BeforeValidator(_time_query), _TIME_SCHEMA]
_WHEN = "UNIX seconds UTC, or ISO 8601 with a zone (2026-12-01T14:30:00Z)"
#: Start of a time window (inclusive).
TimeFrom = Annotated[TimeQuery, Query(description=f"window start: {_WHEN}")]
#: End of a time window (inclusive).
TimeTo = Annotated[TimeQuery, Query(description=f"window end: {_WHEN}")]
#: A track class filter (``?class=``).
TrackClass = Annotated[Literal["vehicle", "human"] | None, Query(alias="class")]
#: Tracks seen by this sensor.
TrackSensor = Annotated[str | None, Query(max_length=200, description="seen by this sensor")]
#: A site-frame box filter.
BBoxQuery = Annotated[str | None, Query(description="e_min,n_min,e_max,n_max (site frame, m)")]
