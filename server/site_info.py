"""What the site endpoints answer: metadata, orthophoto and relief images, roads, elevation.

Renderings are made once per server (:meth:`ConsoleState.cached`). Site-frame
coordinates are ENU metres; ``u_m`` is the local-frame up of a DEM point, ``h_m`` its
height above the WGS84 ellipsoid, and ``elevation_m`` its orthometric height in the
site's vertical datum (:func:`sea_level_geoid`: the geoid ``site.json`` states, evaluated
at the point: EGM96 through PROJ's 15' grid ``egm96_15.gtx``, a national grid, or a
constant ``N``; EGM96 for a site that states none, when the grid is installed), named by
``elevation_datum``.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.errors import GeoidError, NotFoundError, QueryError
from demtrack.core.geo.geoid import GeoidModel, default_grid_dirs, find_grid
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
    "orthometric_in",
    "orthophoto_png",
    "relief_png",
    "roads_geojson",
    "sea_level_geoid",
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
        elevation_datum=sea_level_geoid(site).datum,
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
    env = [Path(p) for p in os.environ.get("PROJ_DATA", "").split(os.pathsep) if p]
    return find_grid(GEOID_GRID, [*default_grid_dirs(), *env])


@functools.lru_cache(maxsize=1)
def _egm96() -> GeoidModel | None:
    path = geoid_grid_path()
    return None if path is None else GeoidModel.from_grid(path, "EGM96")


def sea_level_geoid(site: Any) -> GeoidModel:
    """The geoid of the heights people read as sea level (readout, KML, GPX) at ``site``.

    The site's own vertical datum (``site.geoid``: EGM96, a national grid, a stated
    constant); for a site that states none (ellipsoidal), EGM96 when its grid is
    installed, since those readers expect sea level; else none, and every height says it
    is ellipsoidal. An object without ``geoid`` (an old caller) is read by its constant
    ``geoid_undulation_m``.
    """
    geoid = getattr(site, "geoid", None)
    if geoid is None:
        n = float(getattr(site, "geoid_undulation_m", 0.0) or 0.0)
        geoid = GeoidModel.constant(n) if n else GeoidModel.ellipsoidal()
    if geoid.orthometric:
        return geoid
    return _egm96() or geoid


def orthometric_in(
    geoid: GeoidModel, lat_deg: float, lon_deg: float, h_m: float
) -> tuple[float, str, float]:
    """A point's height above ``geoid``, the datum's name and the undulation ``N`` (m).

    ``(h, "WGS84 ellipsoid (no geoid model)", 0)`` for an ellipsoidal model;
    :class:`~demtrack.core.errors.GeoidError` for a point the grid does not cover.
    """
    n = float(geoid.undulation_m(lat_deg, lon_deg))
    return h_m - n, geoid.datum, n


def orthometric(
    lat_deg: float, lon_deg: float, h_m: float, stated_undulation_m: float
) -> tuple[float, str]:
    """A point's height above the geoid and the name of that datum (EGM96 first).

    Parameters
    ----------
    lat_deg, lon_deg : float
        WGS84 position (degrees).
    h_m : float
        Height above the WGS84 ellipsoid (m).
    stated_undulation_m : float
        A stated constant geoid undulation ``N`` (``h = H + N``), used when the EGM96
        grid is not installed.

    Returns
    -------
    (float, str)
        ``H`` (m) and its datum: ``"EGM96 geoid"`` (grid evaluated at the point), else
        ``"geoid of the site (N = ... m, stated)"``, else, with nothing stated,
        ``"WGS84 ellipsoid (no geoid model)"``. (The readout itself follows the site's
        vertical datum: :func:`sea_level_geoid`.)
    """
    geoid = _egm96()
    if geoid is None:
        n = float(stated_undulation_m)
        geoid = GeoidModel.constant(n) if n else GeoidModel.ellipsoidal()
    big_h, datum, _ = orthometric_in(geoid, lat_deg, lon_deg, h_m)
    return big_h, datum


def elevation_at(state: ConsoleState, e: float, n: float) -> dict[str, Any]:
    """The DEM surface at ``(e, n)`` (site frame, m) and that ground point in WGS84.

    ``u_m``: the DEM surface's local-frame up (m), None off the DEM or in a hole; ``h_m``:
    height above the WGS84 ellipsoid of that ground point (of ``u = 0`` when None);
    ``elevation_m``: its orthometric height ``h - N`` (None where ``u_m`` is), in the
    datum ``elevation_datum`` names (:func:`sea_level_geoid`: the site's own, e.g.
    ``"EGM96 geoid"``); ``undulation_m``: that ``N`` at the point (0 when the datum is the
    ellipsoid); ``mgrs`` (1 m) and ``utm`` (``17T 629933E
    4467728N``) of the point, None at the poles.
    :class:`QueryError` for a point more than 10 000 km from the anchor or
    off the site's geoid grid.
    """
    if max(abs(e), abs(n)) > 1e7:
        raise QueryError(f"point ({e}, {n}) is too far from the site frame's anchor")
    z = float(state.site.dem.sample(np.array([e]), np.array([n]))[0])
    u = z if np.isfinite(z) else None
    lat, lon, h = state.site.frame.to_geodetic(e, n, 0.0 if u is None else u)
    geoid = sea_level_geoid(state.site)
    try:
        big_h, datum, n_m = orthometric_in(geoid, float(lat), float(lon), float(h))
    except GeoidError as exc:
        raise QueryError(f"point ({e}, {n}): {exc}") from None
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
        "undulation_m": n_m,
        # grid references of the point (None at the poles)
        "mgrs": refs["mgrs"],
        "utm": None if refs["utm"] is None else refs["utm"]["text"],
    }
