"""``/api/site``: metadata, orthophoto, DEM relief, roads."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Response
from starlette.concurrency import run_in_threadpool

from demtrack.core.site.orthophoto import read_orthophoto
from demtrack.core.site.road_io import roads_to_geojson
from demtrack.core.terrain.grid import GridSpec

from ..imagery import png_bytes, relief_rgba
from ..models import GridOut, SiteOut
from ..state import ConsoleState, StateDep

__all__ = ["router"]

router = APIRouter(prefix="/api/site", tags=["site"])
_PNG = {"content": {"image/png": {}}, "description": "PNG image"}
_HEIGHTS = "site-frame z (u_m, DEM elevations) is local up; h_m is height above the WGS84 ellipsoid"


def _grid(g: GridSpec) -> GridOut:
    return GridOut(
        x_min=g.x_min,
        y_max=g.y_max,
        cell_m=g.cell_m,
        nrows=g.nrows,
        ncols=g.ncols,
        bounds_enu=g.bounds,
    )


def _ortho(state: ConsoleState) -> tuple[np.ndarray, GridSpec] | None:
    path = state.site.orthophoto_path
    return None if path is None else state.cached("ortho", lambda: read_orthophoto(path))


@router.get("", response_model=SiteOut, summary="Site metadata")
def site_metadata(state: StateDep) -> SiteOut:
    """Frame anchor, CRS, vertical datum, DEM grid and bounds, layers and sensors."""
    site = state.site
    g = site.dem.grid
    x0, y0, x1, y1 = g.bounds
    xs, ys = np.array([x0, x1, x1, x0]), np.array([y0, y0, y1, y1])
    lat, lon, _ = site.frame.to_geodetic(xs, ys, np.zeros(4))
    ortho = _ortho(state)
    fr = site.frame.to_dict()
    return SiteOut(
        name=site.name,
        frame=fr,
        vertical_datum=site.dem.vertical_datum,
        geoid_undulation_m=site.geoid_undulation_m,
        heights=_HEIGHTS,
        crs_wkt=site.dem.crs_wkt,
        dem=_grid(g),
        elevation_range_m=site.dem.elevation_range(),
        bounds_lonlat=(float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max())),
        orthophoto=None if ortho is None else _grid(ortho[1]),
        roads=0 if site.roads is None else len(site.roads),
        sensors=sorted(site.sensors),
    )


@router.get("/orthophoto.png", response_class=Response, responses={200: _PNG}, summary="Orthophoto")
async def orthophoto(state: StateDep) -> Response:
    """The orthophoto on its own grid (see ``orthophoto`` in the metadata)."""
    if state.site.orthophoto_path is None:
        raise HTTPException(404, "this site has no orthophoto")

    def make() -> bytes:
        return state.cached("ortho.png", lambda: png_bytes(_ortho(state)[0]))  # type: ignore[index]

    return Response(await run_in_threadpool(make), media_type="image/png")


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
    data = await run_in_threadpool(
        state.cached, f"relief:{kind}", lambda: png_bytes(relief_rgba(state.site.dem, kind))
    )
    return Response(data, media_type="image/png")


@router.get("/roads.geojson", summary="Road centre lines")
def roads(
    state: StateDep,
    frame: Literal["lonlat", "enu"] = Query(
        "lonlat", description="coordinates: lon/lat or site-frame east/north metres"
    ),
) -> dict[str, Any]:
    """GeoJSON FeatureCollection of the road centre lines."""
    site = state.site
    if site.roads is None:
        return {"type": "FeatureCollection", "features": []}
    if frame == "lonlat":
        return state.cached("roads", lambda: roads_to_geojson(site.roads, site.frame))
    features = [
        {
            "type": "Feature",
            "properties": {"name": name, "width_m": width},
            "geometry": {
                "type": "LineString",
                "coordinates": [[float(x), float(y)] for x, y in line.coords],
            },
        }
        for line, name, width in zip(
            site.roads.lines, site.roads.names, site.roads.widths_m, strict=True
        )
    ]
    return {"type": "FeatureCollection", "frame": "site ENU (m)", "features": features}


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
    if max(abs(e), abs(n)) > 1e7:
        raise HTTPException(422, f"point ({e}, {n}) is too far from the site frame's anchor")
    z = float(state.site.dem.sample(np.array([e]), np.array([n]))[0])
    u = z if np.isfinite(z) else None
    lat, lon, h = state.site.frame.to_geodetic(e, n, 0.0 if u is None else u)
    return {
        "e_m": e,
        "n_m": n,
        "u_m": u,
        "lat_deg": float(lat),
        "lon_deg": float(lon),
        "h_m": float(h),
    }
