"""``/api/site``: metadata, orthophoto, DEM relief, roads, elevation."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query, Response
from starlette.concurrency import run_in_threadpool

from .. import site_info
from ..models import SiteOut
from .deps import StateDep

__all__ = ["router"]

router = APIRouter(prefix="/api/site", tags=["site"])
_PNG = {"content": {"image/png": {}}, "description": "PNG image"}


@router.get("", response_model=SiteOut, summary="Site metadata")
def site_metadata(state: StateDep) -> SiteOut:
    """Frame anchor, CRS, vertical datum, DEM grid and bounds, layers and sensors."""
    return site_info.site_out(state)


@router.get("/orthophoto.png", response_class=Response, responses={200: _PNG}, summary="Orthophoto")
async def orthophoto(state: StateDep) -> Response:
    """The orthophoto on its own grid (see ``orthophoto`` in the metadata)."""
    data = await run_in_threadpool(site_info.orthophoto_png, state)
    return Response(data, media_type="image/png")


@router.get(
    "/relief.png",
    response_class=Response,
    responses={200: _PNG},
    summary="DEM hillshade / colour relief",
)
async def relief(
    state: StateDep,
    kind: Literal["hillshade", "relief", "shaded-relief"] = "shaded-relief",
) -> Response:
    """The DEM rendered on its own grid (``dem`` in the metadata); nodata is transparent."""
    data = await run_in_threadpool(site_info.relief_png, state, kind)
    return Response(data, media_type="image/png")


@router.get("/roads.geojson", summary="Road centre lines")
def roads(
    state: StateDep,
    frame: Literal["lonlat", "enu"] = Query(
        "lonlat", description="coordinates: lon/lat or site-frame east/north metres"
    ),
) -> dict[str, Any]:
    """GeoJSON FeatureCollection of the road centre lines."""
    return site_info.roads_geojson(state, frame)


@router.get("/elevation", summary="DEM elevation and WGS84 position of a site point")
def elevation(
    state: StateDep,
    e: float = Query(..., description="east (m, site frame)", allow_inf_nan=False),
    n: float = Query(..., description="north (m, site frame)", allow_inf_nan=False),
) -> dict[str, Any]:
    """The DEM surface at ``(e, n)`` and that ground point in WGS84.

    ``u_m``: DEM elevation (site-frame up, m), null off the DEM or in a hole; ``h_m``:
    height above the WGS84 ellipsoid of that ground point (of ``u = 0`` when null).
    """
    return site_info.elevation_at(state, e, n)
