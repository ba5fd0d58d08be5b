"""``/api/sensors``: cameras, their poses and ground footprints, their stills."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse

from ..models import SensorOut
from ..sensor_info import sensor_image_path, sensor_out, sensors_out
from .deps import StateDep

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
