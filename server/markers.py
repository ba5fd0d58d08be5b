"""Markers: the points operators keep, stored, streamed to every console and exported.

A marker is given either in the site frame (``e_m``, ``n_m`` and optionally ``u_m``: the
DEM surface there when left out) or in WGS84 (``lat_deg``, ``lon_deg``, ``h_m`` above the
ellipsoid); the other form, the MGRS reference (``mgrs`` package, 1 m precision) and the
time as ISO 8601 UTC are worked out here, once, so every console and every export shows
the same figures. Adding or removing one writes the row and its ``marker`` stream message
in one transaction, under the pipeline's lock, so the stream stays in ``seq`` order.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any

import mgrs

from demtrack.core.errors import NotFoundError, QueryError

from .hub import StreamMessage
from .site_info import elevation_at
from .state import ConsoleState
from .store.codec import published_text
from .store.markers import add_marker, delete_marker, list_markers, update_marker

__all__ = [
    "MAX_T_S",
    "create_marker",
    "edit_marker",
    "markers_geojson",
    "mgrs_of",
    "remove_marker",
    "stored_markers",
]

_MGRS = mgrs.MGRS()
#: The latest time a marker may carry (9999-12-31T23:59:59Z, ISO 8601's last year).
MAX_T_S = 253_402_300_799.0


def mgrs_of(lat_deg: float, lon_deg: float) -> str:
    """The MGRS reference of a WGS84 point at 1 m, spaced: ``32U PU 86121 30438``.

    Outside MGRS's latitudes (beyond 80 S / 84 N, where UPS applies) the reference is
    whatever the ``mgrs`` package gives, unspaced.
    """
    ref = str(_MGRS.toMGRS(lat_deg, lon_deg, MGRSPrecision=5))
    if len(ref) == 15 or len(ref) == 14:  # zone (1-2 digits), band, square, 5 + 5 digits
        z = len(ref) - 13
        return f"{ref[: z + 1]} {ref[z + 1 : z + 3]} {ref[z + 3 : z + 8]} {ref[z + 8 :]}"
    return ref


def _iso(t_s: float) -> str:
    return (
        datetime.fromtimestamp(t_s, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
    )


def _finite(name: str, v: Any) -> float:
    if v is None or not math.isfinite(float(v)):
        raise QueryError(f"{name} must be a finite number, got {v!r}")
    return float(v)


def _where(state: ConsoleState, req: dict[str, Any]) -> tuple[float, ...]:
    """``(e, n, u, lat, lon, h)`` of a request with either site-frame or WGS84 figures."""
    frame = state.site.frame
    enu = req.get("e_m") is not None or req.get("n_m") is not None
    geo = req.get("lat_deg") is not None or req.get("lon_deg") is not None
    if enu == geo:
        raise QueryError("give either e_m and n_m (site frame) or lat_deg and lon_deg, not both")
    if enu:
        e, n = _finite("e_m", req.get("e_m")), _finite("n_m", req.get("n_m"))
        u = req.get("u_m")
        if u is None:
            u = elevation_at(state, e, n)["u_m"]
            if u is None:
                raise QueryError(f"no DEM surface at E {e:.1f} N {n:.1f}: give u_m")
        u = _finite("u_m", u)
        lat, lon, h = (float(v) for v in frame.to_geodetic(e, n, u))
    else:
        lat, lon = _finite("lat_deg", req.get("lat_deg")), _finite("lon_deg", req.get("lon_deg"))
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise QueryError(f"lat_deg {lat} / lon_deg {lon} out of range")
        h = _finite("h_m", req.get("h_m", 0.0) if req.get("h_m") is not None else 0.0)
        e, n, u = (float(v) for v in frame.to_enu(lat, lon, h))
    return e, n, u, lat, lon, h


def _publish(state: ConsoleState, seq: int, text: str, payload: dict[str, Any]) -> None:
    state.pipeline.publish([StreamMessage(payload, seq, published_text(text, seq))])


def create_marker(state: ConsoleState, req: dict[str, Any]) -> dict[str, Any]:
    """Store a marker from a request's fields; announce it to every console.

    ``req``: ``t_s`` (UNIX s), ``name`` (default ``M<id>``), ``note``,
    the position (see the module docstring) and ``source`` (free-form provenance).
    """
    t_s = _finite("t_s", req.get("t_s"))
    if not 0 <= t_s <= MAX_T_S:
        raise QueryError(f"t_s must be UNIX seconds from 0 to {MAX_T_S:.0f}, got {t_s}")
    e, n, u, lat, lon, h = _where(state, req)
    body = {
        "t_s": t_s,
        "time_utc": _iso(t_s),
        "name": str(req.get("name") or "").strip(),
        "note": str(req.get("note") or ""),
        "e_m": e,
        "n_m": n,
        "u_m": u,
        "lat_deg": lat,
        "lon_deg": lon,
        "h_m": h,
        "mgrs": mgrs_of(lat, lon),
        "source": dict(req.get("source") or {}),
    }
    with state.pipeline.commits.lock:
        stored, seq, text = add_marker(state.store, body)
        payload = {"type": "marker", "action": "add", "id": stored["id"], "marker": stored}
        _publish(state, seq, text, payload)
    return stored


def edit_marker(state: ConsoleState, marker_id: int, fields: dict[str, Any]) -> dict[str, Any]:
    """Change a marker's ``name`` and/or ``note``; announce it (``action: update``).

    Raises NotFoundError for an unknown id.
    """
    with state.pipeline.commits.lock:
        done = update_marker(state.store, marker_id, fields)
        if done is None:
            raise NotFoundError(f"no marker {marker_id}")
        body, seq, text = done
        payload = {"type": "marker", "action": "update", "id": marker_id, "marker": body}
        _publish(state, seq, text, payload)
    return body


def remove_marker(state: ConsoleState, marker_id: int) -> None:
    """Remove a marker; announce it. Raises NotFoundError for an unknown id."""
    with state.pipeline.commits.lock:
        done = delete_marker(state.store, marker_id)
        if done is None:
            raise NotFoundError(f"no marker {marker_id}")
        seq, text = done
        payload = {"type": "marker", "action": "delete", "id": marker_id, "marker": None}
        _publish(state, seq, text, payload)


def stored_markers(state: ConsoleState) -> list[dict[str, Any]]:
    """Every stored marker, oldest first."""
    return list_markers(state.store)


def markers_geojson(state: ConsoleState) -> dict[str, Any]:
    """The markers as an RFC 7946 FeatureCollection.

    Coordinates ``[lon, lat, h]``, h above the WGS84 ellipsoid; the other figures (site
    frame, MGRS, time) as properties.
    """
    feats = []
    for m in stored_markers(state):
        props = {k: v for k, v in m.items() if k not in ("lat_deg", "lon_deg", "h_m")}
        feats.append(
            {
                "type": "Feature",
                "id": m["id"],
                "geometry": {
                    "type": "Point",
                    "coordinates": [m["lon_deg"], m["lat_deg"], m["h_m"]],
                },
                "properties": props,
            }
        )
    return {"type": "FeatureCollection", "features": feats}


def markers_document(state: ConsoleState, fmt: str) -> str:
    """The markers as GPX waypoints or KML placemarks (orthometric heights; see the docs).

    ``<ele>`` / KML ``absolute`` are heights above the geoid where the site has a model
    (EGM96 with the grid installed), else ellipsoidal, and the document says which.
    """
    from ..core.io.export_waypoints import Waypoint, waypoints_gpx, waypoints_kml
    from .track_export import site_heights, time_base

    points = [
        Waypoint(
            m["name"],
            float(m["lat_deg"]),
            float(m["lon_deg"]),
            float(m["h_m"]),
            float(m["t_s"]),
            "; ".join(x for x in (m.get("note") or "", f"MGRS {m['mgrs']}") if x),
        )
        for m in stored_markers(state)
    ]
    heights = site_heights(state.site)
    times = time_base(None, wall_clock=True)
    write = waypoints_gpx if fmt == "gpx" else waypoints_kml
    return write(points, heights, times, name="demtrack markers")
