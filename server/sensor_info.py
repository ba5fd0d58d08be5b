"""What the sensor endpoints answer: each camera's pose, intrinsics and ground footprint.

Positions are site-frame ENU metres and WGS84 (``h_m`` above the ellipsoid); footprints
(border rays cast onto the DEM) are computed once per sensor.
"""

from __future__ import annotations

from pathlib import Path

from demtrack.core.errors import NotFoundError
from demtrack.core.site.folder import Sensor

from .footprints import footprint
from .models import SensorOut
from .state import ConsoleState

__all__ = ["sensor_image_path", "sensor_out", "sensors_out"]


def sensor_out(state: ConsoleState, sensor: Sensor) -> SensorOut:
    """One sensor with its footprint."""
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


def sensors_out(state: ConsoleState) -> list[SensorOut]:
    """Every sensor, by id."""
    return [sensor_out(state, state.site.sensors[k]) for k in sorted(state.site.sensors)]


def sensor_image_path(state: ConsoleState, sensor_id: str) -> Path:
    """The still image named in ``site.json`` for the sensor.

    Chosen by sensor id, never by a path from the request, and checked to lie inside the
    site folder. :class:`~demtrack.core.errors.UnknownSensorError` for an unknown sensor,
    :class:`NotFoundError` when it has no (such) image.
    """
    sensor = state.site.sensor(sensor_id)
    path = sensor.image_path
    root = state.site.root.resolve()
    if path is None or not path.resolve().is_relative_to(root) or not path.is_file():
        raise NotFoundError(f"sensor {sensor_id!r} has no image")
    return path
