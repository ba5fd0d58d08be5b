"""Sensor ground footprints: the image border's rays cast onto the DEM.

The footprint polygon joins, in order round the image border, the first terrain hit of
each border ray. A ray that meets no terrain (above the horizon, off the DEM) contributes
the point where it leaves the DEM's extent instead, and the footprint says it is
incomplete. Occlusion inside the border is not shown: this is the frustum's outline on
the ground, not a viewshed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from demtrack.core.camera.pinhole import Camera
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.raycast.cast import RayCaster

__all__ = ["border_pixels", "footprint"]


def border_pixels(width: int, height: int, per_edge: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Pixels round the image border, clockwise from the top-left corner, shape (4 * per_edge,).

    The border is the image's outer edge, ``u in [-0.5, width - 0.5]``, ``v`` likewise.
    """
    s = np.linspace(0.0, 1.0, per_edge, endpoint=False)
    u0, u1, v0, v1 = -0.5, width - 0.5, -0.5, height - 0.5
    u = np.concatenate(
        [u0 + s * (u1 - u0), np.full(per_edge, u1), u1 - s * (u1 - u0), np.full(per_edge, u0)]
    )
    v = np.concatenate(
        [np.full(per_edge, v0), v0 + s * (v1 - v0), np.full(per_edge, v1), v1 - s * (v1 - v0)]
    )
    return u, v


def _exit_point(origin: np.ndarray, d: np.ndarray, bounds: tuple[float, ...]) -> np.ndarray | None:
    """Where the ray's ground track leaves the box ``(x0, y0, x1, y1)``, if it does."""
    x0, y0, x1, y1 = bounds
    t_exit = np.inf
    for k, (lo, hi) in enumerate(((x0, x1), (y0, y1))):
        if abs(d[k]) < 1e-12:
            if not lo <= origin[k] <= hi:
                return None
            continue
        ta, tb = (lo - origin[k]) / d[k], (hi - origin[k]) / d[k]
        t_exit = min(t_exit, max(ta, tb))
    if not np.isfinite(t_exit) or t_exit <= 0:
        return None
    return origin + t_exit * d


def footprint(
    camera: Camera,
    caster: RayCaster,
    frame: LocalFrame,
    per_edge: int = 16,
    max_range_m: float = 5000.0,
    decimals: int | None = None,
) -> dict[str, Any]:
    """The ground footprint of ``camera``.

    ``decimals``: round the ENU points to that many decimals of a metre and lon/lat to
    five more of a degree (None: full precision), for footprints sent often.

    Returns
    -------
    dict
        ``enu``: ``[[e, n, u], ...]`` (m, site frame) round the border; ``lonlat``: a
        GeoJSON Polygon (closed ring of ``[lon, lat]``); ``complete``: every border ray
        hit the terrain; ``n_rays`` and ``n_missed``.
    """
    intr = camera.intrinsics
    u, v = border_pixels(intr.width, intr.height, per_edge)
    origins, dirs = camera.pixel_to_ray(u, v)
    hits = caster.cast(origins, dirs, max_range_m, mode="first")
    pts, missed = [], 0
    for i in range(len(u)):
        lo, hi = int(hits.offsets[i]), int(hits.offsets[i + 1])
        if hi > lo:
            pts.append(hits.points[lo])
            continue
        missed += 1
        p = _exit_point(origins[i], dirs[i], caster.grid.bounds)
        if p is not None:
            pts.append(p)
    enu = np.array(pts, dtype=np.float64).reshape(-1, 3)
    ring: list[list[float]] = []
    if len(enu):
        lat, lon, _ = (np.atleast_1d(a) for a in frame.to_geodetic(*enu.T))
        if decimals is not None:
            enu, lon, lat = enu.round(decimals), lon.round(decimals + 5), lat.round(decimals + 5)
        ring = [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]
        ring.append(ring[0])
    return {
        "enu": [[float(x) for x in p] for p in enu],
        "lonlat": {"type": "Polygon", "coordinates": [ring] if ring else []},
        "complete": missed == 0,
        "n_rays": len(u),
        "n_missed": missed,
    }
