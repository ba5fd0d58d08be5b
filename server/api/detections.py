"""``/api/detections``: ingest batches from camera processes; list what is stored."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Query
from starlette.concurrency import run_in_threadpool
from starlette.responses import Response

from .. import listing
from ..ingest.validate import relative_to
from ..json_response import json_response
from ..models import DetectionBatch, IngestAck, StoredDetectionOut
from .deps import OPERATOR, READER, SQLITE_INT_MAX, StateDep, TimeFrom, TimeTo
from .errors import error_responses

__all__ = ["router"]

router = APIRouter(prefix="/api/detections", tags=["detections"])


@router.post(
    "",
    response_model=IngestAck,
    dependencies=OPERATOR,
    responses=error_responses(401, 413, 422, 503, 507),
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
    records = relative_to(batch.detections, batch.epoch_s)
    return await run_in_threadpool(state.pipeline.ingest, records, batch.batch_key)


@router.get(
    "",
    response_model=list[StoredDetectionOut],
    dependencies=READER,
    responses=error_responses(401, 404, 422),
    summary="Stored detections",
)
def list_detections(
    state: StateDep,
    after_id: int = Query(0, ge=0, le=SQLITE_INT_MAX, description="only ids above this"),
    limit: int = Query(1000, ge=1, le=10_000),
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    sensor: Annotated[
        list[str] | None, Query(description="only these sensors (repeatable)")
    ] = None,
) -> Response:
    """Stored detections in arrival (id) order, for paging with ``after_id``.

    With a time window (``t_from`` and/or ``t_to``, UNIX seconds or ISO 8601, inclusive) or a
    ``sensor`` filter they come in time order instead (ties by id): the boxes of a past
    moment, which the console's camera panels show when the timeline is scrubbed back
    further than the fixes it holds. ``after_id`` still applies.
    """
    rows = listing.list_detections(state, after_id, limit, t_from, t_to, sensor)
    # StoredDetectionOut's JSON (``cls`` under its alias ``class``), encoded as it is:
    # up to 10 000 rows are not validated against the model again.
    return json_response(listing.detection_rows(rows))
