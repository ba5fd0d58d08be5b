"""``/api/detections``: ingest batches from camera processes; list what is stored."""

from __future__ import annotations

import math
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query
from starlette.concurrency import run_in_threadpool
from starlette.responses import Response

from demtrack.core.tracking.types import Detection

from ..json_response import json_response
from ..models import DetectionBatch, IngestAck, StoredDetectionOut
from ..security import require_operator, require_reader
from ..state import ConsoleState, StateDep

__all__ = ["router"]

router = APIRouter(prefix="/api/detections", tags=["detections"])


@router.post(
    "",
    response_model=IngestAck,
    dependencies=[Depends(require_operator)],
    summary="Ingest a batch of detections",
)
async def ingest(batch: DetectionBatch, state: StateDep) -> dict[str, Any]:
    """Store a batch of detections; acknowledged only once durable.

    Checks each record, stores the accepted ones, and acknowledges once the transaction has
    committed (WAL, ``synchronous=FULL``). The batch is then geolocated and tracked, and
    the fixes and track updates go out on ``/ws``. Needs the operator token.
    """
    limit = state.settings.max_batch
    if len(batch.detections) > limit:
        raise HTTPException(413, f"batch has {len(batch.detections)} records; the limit is {limit}")
    return await run_in_threadpool(state.pipeline.ingest, batch.detections, batch.batch_key)


@router.get(
    "",
    response_model=list[StoredDetectionOut],
    dependencies=[Depends(require_reader)],
    summary="Stored detections",
)
def list_detections(
    state: StateDep,
    after_id: int = Query(0, ge=0, description="only ids above this"),
    limit: int = Query(1000, ge=1, le=10_000),
    t_from: float | None = Query(
        None, allow_inf_nan=False, description="only detections at or after this time (s)"
    ),
    t_to: float | None = Query(
        None, allow_inf_nan=False, description="only detections at or before this time (s)"
    ),
    sensor: Annotated[
        list[str] | None, Query(description="only these sensors (repeatable)")
    ] = None,
) -> Response:
    """Stored detections in arrival (id) order, for paging with ``after_id``.

    With a time window (``t_from`` and/or ``t_to``, session seconds, inclusive) or a
    ``sensor`` filter they come in time order instead (ties by id): the boxes of a past
    moment, which the console's camera panels show when the timeline is scrubbed back
    further than the fixes it holds. ``after_id`` still applies.
    """
    if t_from is not None and t_to is not None and t_to < t_from:
        raise HTTPException(422, f"t_to ({t_to}) is before t_from ({t_from})")
    if t_from is None and t_to is None and not sensor:
        rows = state.store.detections(after_id, limit)
    else:
        known = state.site.sensors
        unknown = [s for s in sensor or [] if s not in known]
        if unknown:
            raise HTTPException(404, f"unknown sensor {unknown[0]!r}")
        rows = _in_window(state, t_from, t_to, sorted(set(sensor or known)), after_id, limit)
    # StoredDetectionOut's JSON (``cls`` under its alias ``class``), encoded as it is:
    # up to 10 000 rows are not validated against the model again.
    return json_response(
        [
            {
                "id": i,
                "t": d.t_s,
                "sensor": d.sensor,
                "bbox": d.bbox,
                "class": d.cls,
                "score": d.score,
                "local_id": d.local_id,
            }
            for i, d in rows
        ]
    )


def _in_window(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    sensors: list[str],
    after_id: int,
    limit: int,
) -> list[tuple[int, Detection]]:
    """Detections of ``sensors`` in ``[t_from, t_to]`` (open ends: unbounded), by time, then id."""
    lo = -math.inf if t_from is None else t_from
    hi = math.inf if t_to is None else t_to
    return state.store.detections_in_window(sensors, lo, hi, after_id, limit)
