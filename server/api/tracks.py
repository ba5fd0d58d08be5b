"""``/api/tracks``: the tracker's tracks with time-window, class, sensor and box filters.

``/api/tracks/export?format=geojson|csv|gpx|kml|gpkg`` writes the same selection with the
writers of :mod:`demtrack.core.io.track_io` (the ``demtrack track`` CLI's formats).
"""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from ..json_response import json_response
from ..models import TracksOut
from ..track_export import EXPORT_TYPES, export_bytes, parse_epoch
from ..track_query import filter_tracks, stored_track
from .deps import BBoxQuery, StateDep, TimeFrom, TimeTo, TrackClass, TrackSensor

__all__ = ["router"]

router = APIRouter(prefix="/api/tracks", tags=["tracks"])


@router.get("", response_model=TracksOut, summary="Tracks")
def list_tracks(
    state: StateDep,
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    cls: TrackClass = None,
    sensor: TrackSensor = None,
    bbox: BBoxQuery = None,
) -> Response:
    """Tracks matching every filter given.

    A track is listed when it has a point in the time window (its points are clipped to
    it), is of the class, was seen by the sensor, and passes through the box.
    """
    # Stored bodies have exactly TrackBody's keys (clip sets ``first_index``): encoded
    # as they are, without FastAPI validating every point against the model again.
    return json_response({"tracks": filter_tracks(state, t_from, t_to, cls, sensor, bbox)})


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
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    cls: TrackClass = None,
    sensor: TrackSensor = None,
    bbox: BBoxQuery = None,
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
    when = parse_epoch(epoch)
    bodies = filter_tracks(state, t_from, t_to, cls, sensor, bbox)
    data = await run_in_threadpool(export_bytes, format, bodies, state.site.frame, when)
    media, suffix = EXPORT_TYPES[format]
    return Response(
        data,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="tracks{suffix}"'},
    )


@router.get("/{track_id}", response_model=TracksOut, summary="One track")
def get_track(track_id: int, state: StateDep) -> dict[str, Any]:
    """One track with all its points."""
    return {"tracks": [stored_track(state, track_id)]}
