"""``/api/detections``: ingest batches from camera processes; list what is stored."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query
from starlette.concurrency import run_in_threadpool

from ..models import DetectionBatch, IngestAck, StoredDetectionOut
from ..security import require_operator, require_reader
from ..state import StateDep

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
) -> list[dict[str, Any]]:
    """Stored detections in arrival (id) order, for paging with ``after_id``."""
    return [
        {
            "id": i,
            "t": d.t_s,
            "sensor": d.sensor,
            "bbox": d.bbox,
            "cls": d.cls,
            "score": d.score,
            "local_id": d.local_id,
        }
        for i, d in state.store.detections(after_id, limit)
    ]
