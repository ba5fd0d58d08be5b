"""What the site endpoints answer: metadata, orthophoto and relief images, roads, elevation.

Renderings are made once per server (:meth:`ConsoleState.cached`). Site-frame
coordinates are ENU metres; ``u_m`` is the local-frame up of a DEM point, ``h_m`` its
height above the WGS84 ellipsoid, and ``elevation_m`` its orthometric height (above the
EGM96 geoid, through its 15' grid evaluated at the point, when the PROJ grid
``egm96_15.gtx`` is installed, e.g. by Debian's proj-data; else above the geoid the
site states with its constant ``geoid_undulation_m``), named by ``elevation_datum``.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np
from pyproj import Transformer

from demtrack.core.errors import NotFoundError, QueryError
from demtrack.core.geo.grid_ref import grid_refs
from demtrack.core.site.orthophoto import read_orthophoto
from demtrack.core.site.road_io import roads_to_geojson
from demtrack.core.terrain.grid import GridSpec

from .imagery import png_bytes, relief_rgba
from .models import GridOut, SiteOut
from .state import ConsoleState

__all__ = [
    "elevation_at",
    "geoid_grid_path",
    "orthometric",
    "orthophoto_png",
    "relief_png",
    "roads_geojson",
    "site_out",
]

#: The geoid grid the readout uses, looked for in PROJ's data folders (and Debian's).
GEOID_GRID = "egm96_15.gtx"

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


@functools.lru_cache(maxsize=1)
def geoid_grid_path() -> Path | None:
    """The EGM96 grid file (:data:`GEOID_GRID`) if PROJ's data folders or Debian's hold it."""
    import pyproj.datadir

    dirs = [pyproj.datadir.get_data_dir(), *os.environ.get("PROJ_DATA", "").split(os.pathsep)]
    dirs += ["/usr/share/proj", "/usr/local/share/proj"]
    for d in dirs:
        for part in str(d).split(os.pathsep):
            if part and (Path(part) / GEOID_GRID).is_file():
                return Path(part) / GEOID_GRID
    return None


@functools.lru_cache(maxsize=1)
def _egm96() -> Transformer | None:
    path = geoid_grid_path()
    if path is None:
        return None
    # (lon, lat, h above WGS84) -> (lon, lat, H above EGM96): H = h - N(lat, lon)
    # (vgridshift adds multiplier x grid value).
    return Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad"
        f" +step +proj=vgridshift +grids={path} +multiplier=-1"
        " +step +proj=unitconvert +xy_in=rad +xy_out=deg"
    )


def orthometric(
    lat_deg: float, lon_deg: float, h_m: float, stated_undulation_m: float
) -> tuple[float, str]:
    """A point's height above the geoid and the name of that datum.

    Parameters
    ----------
    lat_deg, lon_deg : float
        WGS84 position (degrees).
    h_m : float
        Height above the WGS84 ellipsoid (m).
    stated_undulation_m : float
        The site's stated constant geoid undulation ``N`` (``h = H + N``), used when the
        EGM96 grid is not installed.

    Returns
    -------
    (float, str)
        ``H`` (m) and its datum: ``"EGM96 geoid"`` (grid evaluated at the point), else
        ``"geoid of the site (N = ... m, stated)"``, else, with nothing stated,
        ``"WGS84 ellipsoid (no geoid model)"``.
    """
    tr = _egm96()
    if tr is not None:
        _, _, big_h = tr.transform(lon_deg, lat_deg, h_m)
        if np.isfinite(big_h):
            return float(big_h), "EGM96 geoid"
    if stated_undulation_m:
        return (
            h_m - stated_undulation_m,
            f"geoid of the site (N = {stated_undulation_m:g} m, stated)",
        )
    return h_m, "WGS84 ellipsoid (no geoid model)"


def elevation_at(state: ConsoleState, e: float, n: float) -> dict[str, Any]:
    """The DEM surface at ``(e, n)`` (site frame, m) and that ground point in WGS84.

    ``u_m``: the DEM surface's local-frame up (m), None off the DEM or in a hole; ``h_m``:
    height above the WGS84 ellipsoid of that ground point (of ``u = 0`` when None);
    ``elevation_m``: its orthometric height (None where ``u_m`` is), in
    ``elevation_datum`` (:func:`orthometric`); ``mgrs`` (1 m) and ``utm`` (``17T 629933E
    4467728N``) of the point, None at the poles. :class:`QueryError` for a point more than
    10 000 km from the anchor.
    """
    if max(abs(e), abs(n)) > 1e7:
        raise QueryError(f"point ({e}, {n}) is too far from the site frame's anchor")
    z = float(state.site.dem.sample(np.array([e]), np.array([n]))[0])
    u = z if np.isfinite(z) else None
    lat, lon, h = state.site.frame.to_geodetic(e, n, 0.0 if u is None else u)
    big_h, datum = orthometric(
        float(lat), float(lon), float(h), float(state.site.geoid_undulation_m)
    )
    refs = grid_refs(float(lat), float(lon))
    return {
        "e_m": e,
        "n_m": n,
        "u_m": u,
        "lat_deg": float(lat),
        "lon_deg": float(lon),
        "h_m": float(h),
        "elevation_m": None if u is None else big_h,
        "elevation_datum": datum,
        # grid references of the point (None at the poles)
        "mgrs": refs["mgrs"],
        "utm": None if refs["utm"] is None else refs["utm"]["text"],
    }
