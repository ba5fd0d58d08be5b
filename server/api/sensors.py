"""``/api/sensors``: cameras, their poses and ground footprints, their stills, pose telemetry."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import FileResponse, Response
from starlette.concurrency import run_in_threadpool

from ..models import SensorOut
from ..pose_models import PoseAckOut, PoseBatchIn
from ..sensor_info import pose_export, sensor_image_path, sensor_out, sensors_out
from .deps import OPERATOR, READER, StateDep, TimeFrom, TimeTo
from .errors import error_responses

__all__ = ["router"]

router = APIRouter(prefix="/api/sensors", tags=["sensors"])


@router.get("", response_model=list[SensorOut], summary="All sensors")
def list_sensors(state: StateDep) -> list[SensorOut]:
    """Every sensor with its ground footprint (border rays cast onto the DEM)."""
    return sensors_out(state)


@router.get("/{sensor_id}", response_model=SensorOut, summary="One sensor")
def get_sensor(sensor_id: str, state: StateDep) -> SensorOut:
    """One sensor with its footprint."""
    return sensor_out(state, state.site.sensor(sensor_id))


@router.post(
    "/{sensor_id}/poses",
    response_model=PoseAckOut,
    dependencies=OPERATOR,
    responses=error_responses(401, 404, 413, 422, 503, 507),
    summary="Ingest a batch of the sensor's pose telemetry",
)
async def ingest_poses(sensor_id: str, batch: PoseBatchIn, state: StateDep) -> dict[str, Any]:
    """Store a batch of pose samples; acknowledged only once durable.

    Checks each record (bad ones are counted by reason and skipped), stores the others in
    one committed transaction (idempotent by ``batch_key``, as detection batches), and
    then merges them into the sensor's pose series: detections of the sensor are
    geolocated with the pose of their moment. A sensor that reports poses is
    telemetry-driven from then on, ``active`` in ``site.json`` or not. Needs the operator
    token; 404 for a sensor the site does not have.
    """
    limit = state.settings.max_batch
    if len(batch.poses) > limit:
        raise HTTPException(413, f"batch has {len(batch.poses)} records; the limit is {limit}")
    state.site.sensor(sensor_id)  # 404 before the body is parsed further
    return await run_in_threadpool(
        state.poses.accept_records, sensor_id, batch.poses, batch.batch_key
    )


@router.get(
    "/{sensor_id}/poses",
    summary="Export the sensor's stored poses",
    dependencies=READER,
    response_class=Response,
    responses={
        **error_responses(401, 404, 422),
        200: {
            "description": "the poses in time order",
            "content": {"application/json": {}, "text/csv": {}, "application/x-ndjson": {}},
        },
    },
)
def export_poses(
    sensor_id: str,
    state: StateDep,
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    format: Literal["json", "csv", "jsonl"] = Query("json", description="file format"),
) -> Response:
    """The stored poses in ``[t_from, t_to]``, with ``time_utc`` (ISO 8601 UTC).

    ``csv`` and ``jsonl`` are the pose file formats ``demtrack`` reads (written by the
    same writer); ``json`` is ``{"sensor", "poses": [...]}``.
    """
    state.site.sensor(sensor_id)
    data, media = pose_export(state, sensor_id, t_from, t_to, format)
    return Response(data, media_type=media)


@router.get(
    "/{sensor_id}/image",
    response_class=FileResponse,
    summary="The sensor's still",
    responses={200: {"content": {"image/png": {}}}},
)
def sensor_image(sensor_id: str, state: StateDep) -> FileResponse:
    """The still image named in ``site.json``.

    The only files served: chosen by sensor id, never by a path from the request, and
    checked to lie inside the site folder.
    """
    return FileResponse(sensor_image_path(state, sensor_id))
