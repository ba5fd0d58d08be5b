"""``/api/geolocate``: pixel (+ sensor, + rule) -> every terrain hit, as the CLI gives it."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fastapi import APIRouter, HTTPException

from demtrack.commands.geolocate import geolocation_to_dict
from demtrack.core.errors import CameraError

from ..models import (
    GeolocateBatchRequest,
    GeolocateBatchResponse,
    GeolocateRequest,
    GeolocationOut,
)
from ..state import ConsoleState, StateDep
from .sensors import sensor_or_404

__all__ = ["router"]

router = APIRouter(prefix="/api/geolocate", tags=["geolocate"])


def _run(
    state: ConsoleState,
    sensor_id: str,
    pixels: Sequence[tuple[float, float]],
    rule: str,
    sigma: float,
) -> list[dict[str, Any]]:
    sensor = sensor_or_404(state, sensor_id)
    geo = state.site.geolocator(pixel_sigma_px=sigma)
    u = [p[0] for p in pixels]
    v = [p[1] for p in pixels]
    try:
        found = geo.geolocate(sensor.camera, u, v, rule=rule)
    except CameraError as exc:  # a pixel off the image: the client's mistake
        raise HTTPException(422, str(exc)) from None
    return [geolocation_to_dict(sensor.id, g) for g in found]


@router.post("", response_model=GeolocationOut, summary="Geolocate one pixel")
def geolocate(req: GeolocateRequest, state: StateDep) -> dict[str, Any]:
    """Every terrain hit of the pixel's ray, the rule's choice and the road point.

    Same content as ``demtrack geolocate --json``.
    """
    return _run(state, req.sensor, [(req.u, req.v)], req.rule, req.pixel_sigma_px)[0]


@router.post("/batch", response_model=GeolocateBatchResponse, summary="Geolocate pixels")
def geolocate_batch(req: GeolocateBatchRequest, state: StateDep) -> dict[str, Any]:
    """Several pixels of one sensor in one call; answers in request order."""
    return {"results": _run(state, req.sensor, req.pixels, req.rule, req.pixel_sigma_px)}
