"""``/api/sensors``: cameras, their poses and ground footprints, their stills."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse

from demtrack.core.site.folder import Sensor

from ..footprints import footprint
from ..models import SensorOut
from ..state import ConsoleState, StateDep

__all__ = ["router", "sensor_or_404"]

router = APIRouter(prefix="/api/sensors", tags=["sensors"])


def sensor_or_404(state: ConsoleState, sensor_id: str) -> Sensor:
    """The sensor, or HTTP 404 naming the known ones."""
    sensor = state.site.sensors.get(sensor_id)
    if sensor is None:
        known = ", ".join(sorted(state.site.sensors)) or "none"
        raise HTTPException(404, f"unknown sensor {sensor_id!r}; this site has: {known}")
    return sensor


def _out(state: ConsoleState, sensor: Sensor) -> SensorOut:
    cam = sensor.camera
    p = cam.position_enu
    lat, lon, h = state.site.frame.to_geodetic(float(p[0]), float(p[1]), float(p[2]))
    fp = state.cached(
        f"footprint:{sensor.id}", lambda: footprint(cam, state.caster, state.site.frame)
    )
    intr = cam.intrinsics
    return SensorOut(
        id=sensor.id,
        name=sensor.name,
        position_enu=(float(p[0]), float(p[1]), float(p[2])),
        lat_deg=float(lat),
        lon_deg=float(lon),
        h_m=float(h),
        pan_deg=sensor.pan_deg,
        tilt_deg=sensor.tilt_deg,
        width_px=intr.width,
        height_px=intr.height,
        intrinsics={k: float(v) for k, v in intr.to_dict().items()},
        image=sensor.image_path is not None,
        footprint=fp,
    )


@router.get("", response_model=list[SensorOut], summary="All sensors")
def list_sensors(state: StateDep) -> list[SensorOut]:
    """Every sensor with its ground footprint (border rays cast onto the DEM)."""
    return [_out(state, state.site.sensors[k]) for k in sorted(state.site.sensors)]


@router.get("/{sensor_id}", response_model=SensorOut, summary="One sensor")
def get_sensor(sensor_id: str, state: StateDep) -> SensorOut:
    """One sensor with its footprint."""
    return _out(state, sensor_or_404(state, sensor_id))


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
    sensor = sensor_or_404(state, sensor_id)
    path = sensor.image_path
    root = state.site.root.resolve()
    if path is None or not path.resolve().is_relative_to(root) or not path.is_file():
        raise HTTPException(404, f"sensor {sensor_id!r} has no image")
    return FileResponse(path)
