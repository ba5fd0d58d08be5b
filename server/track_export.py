"""Stored track bodies written as files: GeoJSON, CSV, GPX, KML and GeoPackage.

The writers are :mod:`demtrack.core.io.track_io`'s (the ``demtrack track`` CLI's
formats); this module turns the server's stored (possibly clipped) bodies into
:class:`~demtrack.core.tracking.types.Track` values and picks the writer. Heights are
above the WGS84 ellipsoid.
"""

from __future__ import annotations

import io
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.errors import QueryError
from demtrack.core.io.track_io import (
    write_tracks_csv,
    write_tracks_geojson,
    write_tracks_gpkg,
    write_tracks_gpx,
    write_tracks_kml,
)
from demtrack.core.tracking.types import Track, TrackPoint

__all__ = ["EXPORT_TYPES", "export_bytes", "parse_epoch", "track_from_body"]

#: Export format -> (media type, file suffix).
EXPORT_TYPES: dict[str, tuple[str, str]] = {
    "geojson": ("application/geo+json", ".geojson"),
    "csv": ("text/csv; charset=utf-8", ".csv"),
    "gpx": ("application/gpx+xml", ".gpx"),
    "kml": ("application/vnd.google-earth.kml+xml", ".kml"),
    "gpkg": ("application/geopackage+sqlite3", ".gpkg"),
}


def track_from_body(body: dict[str, Any]) -> Track:
    """A :class:`Track` value from a stored (possibly clipped) track body."""
    points = [
        TrackPoint(p["t_s"], [p["e_m"], p["n_m"], p["u_m"]], p["sensors"], p["detection_ids"])
        for p in body["points"]
    ]
    return Track(body["id"], body["cls"], points, body["sensors"], [tuple(g) for g in body["gaps"]])


def parse_epoch(text: str | None) -> datetime:
    """The UTC time of ``t = 0 s``: ISO 8601 ``text``, or 2000-01-01T00:00:00Z when None.

    A time without a zone is taken as UTC; :class:`QueryError` when ``text`` is not ISO 8601.
    """
    if text is None:
        return datetime(2000, 1, 1, tzinfo=UTC)  # as ``demtrack track`` without --epoch
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise QueryError(f"epoch must be an ISO 8601 time, got {text!r}") from None
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def export_bytes(fmt: str, bodies: list[dict[str, Any]], frame: Any, epoch: datetime) -> bytes:
    """The file of format ``fmt`` (a key of :data:`EXPORT_TYPES`) holding ``bodies``.

    ``frame``: the site's :class:`~demtrack.core.geo.geodesy.LocalFrame`, for points the
    bodies do not carry geodetic coordinates of.
    """
    tracks = [track_from_body(b) for b in bodies]
    # The stored points carry their geodetic coordinates: look them up, convert the rest.
    known = {
        (p["e_m"], p["n_m"], p["u_m"]): (p["lat_deg"], p["lon_deg"], p["h_m"])
        for b in bodies
        for p in b["points"]
    }

    def to_geodetic(e: float, n: float, u: float) -> tuple[float, float, float]:
        hit = known.get((e, n, u))
        if hit is not None:
            return hit
        lat, lon, h = (float(np.asarray(v)) for v in frame.to_geodetic(e, n, u))
        return lat, lon, h

    if fmt == "gpkg":
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "tracks.gpkg"
            write_tracks_gpkg(path, tracks, to_geodetic, epoch=epoch)
            return path.read_bytes()
    buf = io.StringIO()
    if fmt == "geojson":
        write_tracks_geojson(buf, tracks, to_geodetic, epoch=epoch)
    elif fmt == "csv":
        write_tracks_csv(buf, tracks, to_geodetic, epoch=epoch)
    elif fmt == "gpx":
        write_tracks_gpx(buf, tracks, to_geodetic, epoch=epoch)
    else:
        write_tracks_kml(buf, tracks, to_geodetic, epoch=epoch)
    return buf.getvalue().encode("utf-8")
