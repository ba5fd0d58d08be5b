"""``/api/tracks``: the tracker's tracks with time-window, class, sensor and box filters.

``/api/tracks/export?format=geojson|csv|gpx|kml|kmz|gpkg`` writes the same selection with
the one writer per format of :mod:`demtrack.core.io.track_io` (which ``demtrack track -o``
and the console's export menu use too).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from ..json_response import json_response
from ..models import TracksOut
from ..time_fields import track_with_times
from ..track_export import EXPORT_TYPES, export_bytes, parse_epoch, site_heights
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
    bodies = filter_tracks(state, t_from, t_to, cls, sensor, bbox)
    return json_response({"tracks": [track_with_times(b) for b in bodies]})


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
    format: Literal["geojson", "csv", "gpx", "kml", "kmz", "gpkg"] = Query(
        "geojson", description="file format"
    ),
    t_from: TimeFrom = None,
    t_to: TimeTo = None,
    cls: TrackClass = None,
    sensor: TrackSensor = None,
    bbox: BBoxQuery = None,
    track: Annotated[
        list[int] | None,
        Query(max_length=10_000, description="only these track ids (repeat the parameter)"),
    ] = None,
    epoch: str | None = Query(
        None,
        max_length=64,
        description="ISO 8601 time with a zone of t = 0 s, declared in the file, for a"
        " store of session seconds (default none: t_s are UNIX seconds, real UTC)",
    ),
) -> Response:
    """The tracks ``GET /api/tracks`` lists for the same filters, as a file.

    GeoJSON (RFC 7946, MultiLineString of lon/lat/h, h ellipsoidal), CSV (one row per
    point, ``longitude``/``latitude``), GPX 1.1 (a segment per run between gaps, ``<time>``
    and ``<ele>``), KML 2.2 / KMZ (a ``gx:Track`` per run, ``absolute`` altitudes) or
    GeoPackage (layers ``tracks`` and ``track_points``, EPSG:4979, R-tree index). Sea-level
    heights (KML, GPX ``ele``) use the site's geoid model; without one they are the
    ellipsoidal heights, and the file says so. Times are real UTC (``t_s`` are UNIX
    seconds); with ``epoch`` they are ``epoch + t_s``, the epoch declared in the file.
    """
    when = parse_epoch(epoch)
    bodies = filter_tracks(state, t_from, t_to, cls, sensor, bbox)
    if track is not None:
        wanted = set(track)
        bodies = [b for b in bodies if b["id"] in wanted]
    heights = site_heights(state.site)
    data = await run_in_threadpool(export_bytes, format, bodies, state.site.frame, when, heights)
    media, suffix = EXPORT_TYPES[format]
    return Response(
        data,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="tracks{suffix}"'},
    )


@router.get("/{track_id}", response_model=TracksOut, summary="One track")
def get_track(track_id: int, state: StateDep) -> dict[str, Any]:
    """One track with all its points."""
    return {"tracks": [track_with_times(stored_track(state, track_id))]}
