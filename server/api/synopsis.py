"""``/api/synopsis``: the activity synopsis of a time window (Collins et al. 1998, Fig. 8).

The trajectories and gaps are computed by :mod:`demtrack.server.synopsis`; the schema is
:mod:`demtrack.server.synopsis_models`.
"""

from __future__ import annotations

from fastapi import APIRouter, Query
from starlette.responses import Response

from ..json_response import json_response
from ..synopsis import window_synopsis
from ..synopsis_models import SynopsisOut
from .deps import StateDep, TimeFrom, TimeTo, TrackClass, TrackSensor

__all__ = ["router"]

router = APIRouter(prefix="/api/synopsis", tags=["synopsis"])


@router.get("", response_model=SynopsisOut, summary="Activity synopsis of a time window")
def get_synopsis(
    state: StateDep,
    t0: TimeFrom = None,
    t1: TimeTo = None,
    cls: TrackClass = None,
    sensor: TrackSensor = None,
    step_s: float = Query(
        1.0, gt=0, le=3600, allow_inf_nan=False, description="path point spacing (s)"
    ),
) -> Response:
    """The long-term trajectories of ``[t0, t1]`` split into tracked parts and gaps.

    Tracks are selected as ``GET /api/tracks`` selects them (points clipped to the
    window). A gap is a stretch longer than the tracker's gap threshold in which no
    sensor saw the target; it lists the sensors before and after and is a hand-off when
    a sensor that had not seen the target picked it up. ``events`` are the stored events
    overlapping the window (``GET /api/events``), only those involving a listed
    trajectory when a class or sensor filter is given.
    """
    # Built with exactly SynopsisOut's keys: encoded as it is, without FastAPI validating
    # every path point against the model again.
    return json_response(window_synopsis(state, t0, t1, cls, sensor, step_s))
