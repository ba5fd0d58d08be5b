"""Pixels of one sensor geolocated on the terrain, as ``demtrack geolocate --json`` gives them.

Every terrain hit of each pixel's viewing ray, the rule's choice and the road point
(:func:`demtrack.core.geolocation.geolocation_json.geolocation_to_dict`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from demtrack.core.geolocation.geolocation_json import geolocation_to_dict

from .state import ConsoleState

__all__ = ["geolocate_pixels"]


def geolocate_pixels(
    state: ConsoleState,
    sensor_id: str,
    pixels: Sequence[tuple[float, float]],
    rule: str,
    sigma_px: float,
) -> list[dict[str, Any]]:
    """The geolocation of each ``(u, v)`` pixel (px) of ``sensor_id``, in order.

    Raises
    ------
    UnknownSensorError
        For a sensor the site does not have.
    CameraError
        For a pixel off the image (the client's mistake).
    """
    sensor = state.site.sensor(sensor_id)
    geo = state.site.geolocator(pixel_sigma_px=sigma_px)
    u = [p[0] for p in pixels]
    v = [p[1] for p in pixels]
    found = geo.geolocate(sensor.camera, u, v, rule=rule)
    return [geolocation_to_dict(sensor.id, g) for g in found]
