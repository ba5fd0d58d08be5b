"""What the site endpoints answer: metadata, orthophoto and relief images, roads, elevation.

Renderings are made once per server (:meth:`ConsoleState.cached`). Site-frame
coordinates are ENU metres; ``u_m`` is a DEM elevation (site-frame up) and ``h_m`` a
height above the WGS84 ellipsoid.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from demtrack.core.errors import NotFoundError, QueryError
from demtrack.core.site.orthophoto import read_orthophoto
from demtrack.core.site.road_io import roads_to_geojson
from demtrack.core.terrain.grid import GridSpec

from .imagery import png_bytes, relief_rgba
from .models import GridOut, SiteOut
from .state import ConsoleState

__all__ = ["elevation_at", "orthophoto_png", "relief_png", "roads_geojson", "site_out"]

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


def site_out(state: ConsoleState) -> SiteOut:
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


def orthophoto_png(state: ConsoleState) -> bytes:
    """The orthophoto as PNG on its own grid; :class:`NotFoundError` if the site has none."""
    if state.site.orthophoto_path is None:
        raise NotFoundError("this site has no orthophoto")
    data: bytes = state.cached("ortho.png", lambda: png_bytes(_ortho(state)[0]))  # type: ignore[index]
    return data


def relief_png(state: ConsoleState, kind: str) -> bytes:
    """The DEM rendered as ``kind`` (:func:`relief_rgba`) on its own grid, as PNG."""
    data: bytes = state.cached(
        f"relief:{kind}", lambda: png_bytes(relief_rgba(state.site.dem, kind))
    )
    return data


def roads_geojson(state: ConsoleState, frame: str) -> dict[str, Any]:
    """GeoJSON FeatureCollection of the road centre lines, ``"lonlat"`` or ``"enu"`` (m)."""
    site = state.site
    if site.roads is None:
        return {"type": "FeatureCollection", "features": []}
    if frame == "lonlat":
        doc: dict[str, Any] = state.cached(
            "roads", lambda: roads_to_geojson(site.roads, site.frame)
        )
        return doc
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


def elevation_at(state: ConsoleState, e: float, n: float) -> dict[str, Any]:
    """The DEM surface at ``(e, n)`` (site frame, m) and that ground point in WGS84.

    ``u_m``: DEM elevation (site-frame up, m), None off the DEM or in a hole; ``h_m``:
    height above the WGS84 ellipsoid of that ground point (of ``u = 0`` when None).
    :class:`QueryError` for a point more than 10 000 km from the anchor.
    """
    if max(abs(e), abs(n)) > 1e7:
        raise QueryError(f"point ({e}, {n}) is too far from the site frame's anchor")
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
