"""Dependency aliases the routers share: the server state, the auth checks, common queries.

Each alias is an ``Annotated`` type, so an endpoint says what it needs in its signature
(``state: StateDep``, ``t_from: TimeFrom = None``) and the OpenAPI description of a
parameter is written once.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import Depends, Query, Request

from ..security import require_operator, require_reader
from ..state import ConsoleState

__all__ = [
    "OPERATOR",
    "READER",
    "SQLITE_INT_MAX",
    "BBoxQuery",
    "StateDep",
    "TimeFrom",
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

#: Start of a time window (session seconds, inclusive).
TimeFrom = Annotated[float | None, Query(description="window start (s)", allow_inf_nan=False)]
#: End of a time window (session seconds, inclusive).
TimeTo = Annotated[float | None, Query(description="window end (s)", allow_inf_nan=False)]
#: A track class filter (``?class=``).
TrackClass = Annotated[Literal["vehicle", "human"] | None, Query(alias="class")]
#: Tracks seen by this sensor.
TrackSensor = Annotated[str | None, Query(max_length=200, description="seen by this sensor")]
#: A site-frame box filter.
BBoxQuery = Annotated[str | None, Query(description="e_min,n_min,e_max,n_max (site frame, m)")]
