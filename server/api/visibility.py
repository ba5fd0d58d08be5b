"""Visibility for the map: ``/api/sensors/{id}/viewshed.geojson``, ``/api/site/coverage.*``.

The viewsheds, the coverage raster and the blind spots are computed (and cached) by
:mod:`demtrack.server.visibility_service`, in a worker thread.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response
from starlette.concurrency import run_in_threadpool

from demtrack.core.visibility.target_heights import DEFAULT_TARGET_HEIGHT_M

from .. import visibility_service as vis
from .deps import StateDep

__all__ = ["router"]

router = APIRouter(tags=["visibility"])
_PNG = {"content": {"image/png": {}}, "description": "PNG image"}

TargetHeight = Annotated[
    float,
    Query(
        ge=0.0,
        le=1000.0,
        allow_inf_nan=False,
        description="target point above the surface (m): about 1.7 for a person, 1.5 for a car",
    ),
]
MaxRange = Annotated[
    float,
    Query(gt=0.0, le=100_000.0, allow_inf_nan=False, description="3-D range limit (m)"),
]
Mode = Annotated[
    Literal["fov", "reachable"],
    Query(description="current field of view, or anywhere the pan-tilt head can point"),
]


@router.get("/api/sensors/{sensor_id}/viewshed.geojson", summary="What a sensor sees")
async def sensor_viewshed(
    sensor_id: str,
    state: StateDep,
    target_height_m: TargetHeight = DEFAULT_TARGET_HEIGHT_M,
    max_range_m: MaxRange = 1000.0,
    mode: Mode = "fov",
    frame: Literal["lonlat", "enu"] = Query(
        "lonlat", description="coordinates: lon/lat (RFC 7946) or site-frame east/north metres"
    ),
) -> dict[str, Any]:
    """GeoJSON FeatureCollection with one MultiPolygon: the cells the sensor sees.

    A cell is seen when the sight line to a point ``target_height_m`` above its centre
    meets no terrain (trees and roofs occlude), within ``max_range_m`` and, for
    ``mode=fov``, inside the image at the sensor's current pan and tilt. The polygons
    follow cell edges; ``properties.area_m2`` = cells x cell area.
    """
    sensor = state.site.sensor(sensor_id)
    return await run_in_threadpool(
        vis.sensor_viewshed_geojson, state, sensor, mode, target_height_m, max_range_m, frame
    )


@router.get(
    "/api/site/coverage.png",
    response_class=Response,
    responses={200: _PNG},
    summary="How many sensors see each cell",
)
async def coverage_png(
    state: StateDep,
    target_height_m: TargetHeight = DEFAULT_TARGET_HEIGHT_M,
    max_range_m: MaxRange = 1000.0,
    mode: Mode = "fov",
) -> Response:
    """The number of sensors that see each cell, on the DEM grid.

    Placed like ``relief.png``: pixel (0, 0) is the north-west cell, the image spans the
    grid's outer bounds. Colours by count (``legend`` in ``coverage.json``); clear where no
    sensor sees the cell.
    """
    data = await run_in_threadpool(vis.coverage_png, state, mode, target_height_m, max_range_m)
    return Response(data, media_type="image/png")


@router.get("/api/site/coverage.json", summary="Coverage per sensor and blind spots")
async def coverage_json(
    state: StateDep,
    target_height_m: TargetHeight = DEFAULT_TARGET_HEIGHT_M,
    max_range_m: MaxRange = 1000.0,
    mode: Mode = "fov",
    min_area_m2: float = Query(
        25.0, ge=0.0, le=1e12, allow_inf_nan=False, description="smallest blind spot listed"
    ),
    limit: int = Query(20, ge=0, le=10_000, description="blind spots listed (largest first)"),
) -> dict[str, Any]:
    """What ``demtrack viewshed`` prints, as JSON.

    The area each sensor sees, the share of the site seen by at least k sensors, and the
    blind spots (8-connected unseen areas of at least ``min_area_m2``), largest first.
    Each listed blind spot has its bounding box (``bbox_enu``) and its outline
    (``outline_enu``: MultiPolygon coordinates in the site frame, m, along cell edges,
    covering exactly the spot's cells; exteriors counter-clockwise).
    """
    return await run_in_threadpool(
        vis.coverage_summary, state, mode, target_height_m, max_range_m, min_area_m2, limit
    )
