"""The JSON form of a :class:`~demtrack.core.geolocation.geolocate.Geolocation`.

One function, shared by ``demtrack geolocate --json`` and ``POST /api/geolocate``, so the
command line and the API give the same document for the same pixel. Site-frame
coordinates are ENU metres; geodetic heights (``h_m``) are above the WGS84 ellipsoid.
Every hit also carries its grid references (``mgrs`` at 1 m and ``utm``:
:func:`demtrack.core.geo.grid_ref.grid_refs`).
"""

from __future__ import annotations

from typing import Any

from ..geo.grid_ref import grid_refs
from .geolocate import Geolocation, GroundHit

__all__ = ["geolocation_to_dict"]


def _hit(h: GroundHit) -> dict[str, Any]:
    return {**h.to_dict(), **grid_refs(h.lat_deg, h.lon_deg)}


def geolocation_to_dict(sensor_id: str, g: Geolocation) -> dict[str, Any]:
    """JSON-ready answer for one pixel.

    Parameters
    ----------
    sensor_id : str
        The sensor the pixel belongs to.
    g : Geolocation
        The pixel's viewing ray and terrain hits.

    Returns
    -------
    dict
        ``sensor``, ``pixel`` ``[u, v]`` (px), ``rule``, ``status``, ``crossed_nodata``,
        ``ray`` (``origin_enu``, ``direction_enu``; site frame, m and unit vector),
        ``selected`` and ``hits`` (each :meth:`GroundHit.to_dict` with ``mgrs`` and
        ``utm``) and ``road`` (or None).
    """
    return {
        "sensor": sensor_id,
        "pixel": [g.u, g.v],
        "rule": g.rule,
        "status": g.status,
        "crossed_nodata": g.crossed_nodata,
        "ray": {
            "origin_enu": [float(x) for x in g.origin_enu],
            "direction_enu": [float(x) for x in g.direction_enu],
        },
        "selected": [_hit(h) for h in g.selected],
        "hits": [_hit(h) for h in g.hits],
        "road": _hit(g.road) if g.road is not None else None,
    }
