"""``/api/geolocate``: pixel (+ sensor, + rule) -> every terrain hit, as the CLI gives it."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from ..models import (
    GeolocateBatchRequest,
    GeolocateBatchResponse,
    GeolocateRequest,
    GeolocationOut,
)
from ..pixel_geolocation import geolocate_pixels
from .deps import StateDep

__all__ = ["router"]

router = APIRouter(prefix="/api/geolocate", tags=["geolocate"])


@router.post("", response_model=GeolocationOut, summary="Geolocate one pixel")
def geolocate(req: GeolocateRequest, state: StateDep) -> dict[str, Any]:
    """Every terrain hit of the pixel's ray, the rule's choice and the road point.

    Same content as ``demtrack geolocate --json``.
    """
    return geolocate_pixels(state, req.sensor, [(req.u, req.v)], req.rule, req.pixel_sigma_px)[0]


@router.post("/batch", response_model=GeolocateBatchResponse, summary="Geolocate pixels")
def geolocate_batch(req: GeolocateBatchRequest, state: StateDep) -> dict[str, Any]:
    """Several pixels of one sensor in one call; answers in request order."""
    found = geolocate_pixels(state, req.sensor, req.pixels, req.rule, req.pixel_sigma_px)
    return {"results": found}
