"""``/api/tracks``: the tracker's tracks with time-window, class, sensor and box filters.

``/api/tracks/export?format=geojson|csv|gpx|kml|gpkg`` writes the same selection with the
writers of :mod:`demtrack.core.io.track_io` (the ``demtrack track`` CLI's formats).
"""

from __future__ import annotations

import io
import tempfile
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from demtrack.core.io.track_io import (
    write_tracks_csv,
    write_tracks_geojson,
    write_tracks_gpkg,
    write_tracks_gpx,
    write_tracks_kml,
)
from demtrack.core.tracking.types import Track, TrackPoint

from ..json_response import json_response
from ..models import TracksOut
from ..state import ConsoleState, StateDep
from ..track_cache import CachedTrack, TrackCache, clip

__all__ = [
    "EXPORT_TYPES",
    "filter_tracks",
    "parse_bbox",
    "router",
    "select_tracks",
    "track_cache",
    "track_from_body",
]

#: Export format -> (media type, file suffix).
EXPORT_TYPES: dict[str, tuple[str, str]] = {
    "geojson": ("application/geo+json", ".geojson"),
    "csv": ("text/csv; charset=utf-8", ".csv"),
    "gpx": ("application/gpx+xml", ".gpx"),
    "kml": ("application/vnd.google-earth.kml+xml", ".kml"),
    "gpkg": ("application/geopackage+sqlite3", ".gpkg"),
}

router = APIRouter(prefix="/api/tracks", tags=["tracks"])


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    """``"e_min,n_min,e_max,n_max"`` (site frame, m) -> tuple; HTTP 422 if malformed."""
    if text is None:
        return None
    try:
        box = tuple(float(x) for x in text.split(","))
    except ValueError:
        box = ()
    if len(box) != 4 or not all(abs(x) < 1e12 for x in box) or box[0] > box[2] or box[1] > box[3]:
        raise HTTPException(
            422, f"bbox must be 'e_min,n_min,e_max,n_max' (m, min <= max), got {text!r}"
        )
    return box  # type: ignore[return-value]


def _in_box(track: dict[str, Any], box: tuple[float, float, float, float]) -> bool:
    return any(
        box[0] <= p["e_m"] <= box[2] and box[1] <= p["n_m"] <= box[3] for p in track["points"]
    )


def track_cache(state: ConsoleState) -> TrackCache:
    """The server's :class:`TrackCache` (one per app, over its store)."""
    cache: TrackCache = state.cached("track_cache", partial(TrackCache, state.store))
    return cache


def select_tracks(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    sensor: str | None,
    bbox: str | None,
) -> list[tuple[CachedTrack, dict[str, Any]]]:
    """Cached tracks passing every filter, each with its body clipped to the window.

    The clipped bodies share their point dicts and lists with the cache: read-only.
    """
    if t_from is not None and t_to is not None and t_from > t_to:
        raise HTTPException(422, f"t_from ({t_from}) is after t_to ({t_to})")
    box = parse_bbox(bbox)
    out = []
    for track in track_cache(state).select(t_from=t_from, t_to=t_to, cls=cls, bbox=box):
        if sensor is not None and sensor not in track.body["sensors"]:
            continue
        clipped = clip(track, t_from, t_to)
        if not clipped["points"] or (box is not None and not _in_box(clipped, box)):
            continue
        out.append((track, clipped))
    return out


def filter_tracks(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    sensor: str | None,
    bbox: str | None,
) -> list[dict[str, Any]]:
    """Stored track bodies passing every filter, points clipped to the window.

    Read-only: the bodies share their point dicts and lists with the server's
    :class:`~demtrack.server.track_cache.TrackCache` (copy before changing anything).
    """
    return [clipped for _, clipped in select_tracks(state, t_from, t_to, cls, sensor, bbox)]


_T_FROM = Query(None, description="window start (s)", allow_inf_nan=False)
_T_TO = Query(None, description="window end (s)", allow_inf_nan=False)
_CLASS = Query(None, alias="class")
_SENSOR = Query(None, max_length=200, description="seen by this sensor")
_BBOX = Query(None, description="e_min,n_min,e_max,n_max (site frame, m)")


@router.get("", response_model=TracksOut, summary="Tracks")
def list_tracks(
    state: StateDep,
    t_from: float | None = _T_FROM,
    t_to: float | None = _T_TO,
    cls: Literal["vehicle", "human"] | None = _CLASS,
    sensor: str | None = _SENSOR,
    bbox: str | None = _BBOX,
) -> Response:
    """Tracks matching every filter given.

    A track is listed when it has a point in the time window (its points are clipped to
    it), is of the class, was seen by the sensor, and passes through the box.
    """
    # Stored bodies have exactly TrackBody's keys (clip sets ``first_index``): encoded
    # as they are, without FastAPI validating every point against the model again.
    return json_response({"tracks": filter_tracks(state, t_from, t_to, cls, sensor, bbox)})


def track_from_body(body: dict[str, Any]) -> Track:
    """A :class:`Track` value from a stored (possibly clipped) track body."""
    points = [
        TrackPoint(p["t_s"], [p["e_m"], p["n_m"], p["u_m"]], p["sensors"], p["detection_ids"])
        for p in body["points"]
    ]
    return Track(body["id"], body["cls"], points, body["sensors"], [tuple(g) for g in body["gaps"]])


def _epoch(text: str | None) -> datetime:
    if text is None:
        return datetime(2000, 1, 1, tzinfo=UTC)  # as ``demtrack track`` without --epoch
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise HTTPException(422, f"epoch must be an ISO 8601 time, got {text!r}") from None
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def _write(fmt: str, bodies: list[dict[str, Any]], frame: Any, epoch: datetime) -> bytes:
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


@router.get(
    "/export",
    summary="Export tracks as a file",
    response_class=Response,
    responses={
        200: {
            "description": "the file (``Content-Disposition: attachment``)",
            "content": {media: {} for media, _ in EXPORT_TYPES.values()},
        }
    },
)
async def export_tracks(
    state: StateDep,
    format: Literal["geojson", "csv", "gpx", "kml", "gpkg"] = Query(
        "geojson", description="file format"
    ),
    t_from: float | None = _T_FROM,
    t_to: float | None = _T_TO,
    cls: Literal["vehicle", "human"] | None = _CLASS,
    sensor: str | None = _SENSOR,
    bbox: str | None = _BBOX,
    epoch: str | None = Query(
        None,
        max_length=64,
        description="ISO 8601 UTC time of t = 0 s (default 2000-01-01T00:00:00Z)",
    ),
) -> Response:
    """The tracks ``GET /api/tracks`` lists for the same filters, as a file.

    GeoJSON (RFC 7946, lon/lat/h), CSV (one row per point), GPX 1.1 (a segment per run
    between gaps), KML 2.2 (a LineString per run; lon,lat,alt) or GeoPackage (layers
    ``tracks`` and ``track_points``, EPSG:4326). Heights are above the WGS84 ellipsoid.
    """
    when = _epoch(epoch)
    bodies = filter_tracks(state, t_from, t_to, cls, sensor, bbox)
    data = await run_in_threadpool(_write, format, bodies, state.site.frame, when)
    media, suffix = EXPORT_TYPES[format]
    return Response(
        data,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="tracks{suffix}"'},
    )


@router.get("/{track_id}", response_model=TracksOut, summary="One track")
def get_track(track_id: int, state: StateDep) -> dict[str, Any]:
    """One track with all its points."""
    body = state.store.track(track_id)
    if body is None:
        raise HTTPException(404, f"no track {track_id}")
    return {"tracks": [body]}
