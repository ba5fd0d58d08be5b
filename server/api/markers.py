"""``/api/markers``: the points operators keep, stored and streamed to every console.

``GET`` lists them (reader), ``POST`` keeps one, ``PATCH /{id}`` renames or notes one and
``DELETE /{id}`` removes one (operator token); each change is streamed as a ``marker``
message. ``GET /api/markers/export``
writes them as GeoJSON (RFC 7946, ``[lon, lat, h]``, h above the WGS84 ellipsoid), CSV
(``longitude``/``latitude`` columns, which GDAL and QGIS detect), GPX waypoints or KML
placemarks (heights above the geoid where the site has a geoid model).
"""

from __future__ import annotations

import csv
import io
from typing import Any, Literal

from fastapi import APIRouter, Path, Query
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from demtrack.core.errors import QueryError
from demtrack.core.io.times import parse_iso_time

from .. import markers
from ..markers import MAX_T_S
from ..messages import MarkerBody
from .deps import OPERATOR, READER, StateDep

__all__ = ["MarkerEdit", "MarkerIn", "MarkersOut", "router"]

router = APIRouter(prefix="/api/markers", tags=["markers"])


class MarkerIn(BaseModel):
    """A marker to keep: its moment, name, note and position (site frame or WGS84)."""

    model_config = ConfigDict(extra="forbid")

    t_s: float | None = Field(
        None,
        ge=0,
        le=MAX_T_S,
        allow_inf_nan=False,
        description="the moment it marks (UNIX s, UTC; up to 9999-12-31); or give time",
    )
    time: str | None = Field(
        None,
        max_length=64,
        description="the moment as ISO 8601 with a zone (2026-12-01T14:32:05Z), in place of t_s",
    )
    name: str = Field("", max_length=200, description="default M<id>")
    note: str = Field("", max_length=4000)
    e_m: float | None = Field(None, allow_inf_nan=False, description="site frame east (m)")
    n_m: float | None = Field(None, allow_inf_nan=False, description="site frame north (m)")
    u_m: float | None = Field(
        None, allow_inf_nan=False, description="site frame up (m); default the DEM surface"
    )
    lat_deg: float | None = Field(None, ge=-90, le=90, allow_inf_nan=False)
    lon_deg: float | None = Field(None, ge=-180, le=180, allow_inf_nan=False)
    h_m: float | None = Field(
        None, allow_inf_nan=False, description="above the WGS84 ellipsoid (m); default 0"
    )
    source: dict[str, Any] = Field(
        default_factory=dict, description="provenance, e.g. {sensor, pixel, rule}"
    )


class MarkerEdit(BaseModel):
    """A marker's new name and/or note (fields left out stay as they are)."""

    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(None, max_length=200, description="empty: M<id>")
    note: str | None = Field(None, max_length=4000)


class MarkersOut(BaseModel):
    """Every stored marker, oldest first."""

    model_config = ConfigDict(extra="forbid")

    markers: list[MarkerBody]


@router.get("", response_model=MarkersOut, summary="Markers", dependencies=READER)
def list_markers(state: StateDep) -> dict[str, Any]:
    """Every stored marker, oldest first."""
    return {"markers": markers.stored_markers(state)}


@router.post(
    "",
    response_model=MarkerBody,
    status_code=201,
    summary="Keep a marker",
    dependencies=OPERATOR,
    responses={422: {"description": "no position, both positions, or no DEM surface there"}},
)
def create_marker(state: StateDep, body: MarkerIn) -> dict[str, Any]:
    """Store a marker and stream it (``marker``, ``action: add``) to every console."""
    req = body.model_dump()
    when = req.pop("time")
    if (when is None) == (req["t_s"] is None):
        raise QueryError("give the marker's moment as t_s (UNIX s) or time (ISO 8601), one of them")
    if when is not None:
        req["t_s"] = parse_iso_time(when, "time")
    return markers.create_marker(state, req)


_MARKER_ID = Path(ge=1, le=2**62)


@router.patch(
    "/{marker_id}",
    response_model=MarkerBody,
    summary="Rename or note a marker",
    dependencies=OPERATOR,
    responses={404: {"description": "no such marker"}},
)
def edit_marker(state: StateDep, body: MarkerEdit, marker_id: int = _MARKER_ID) -> dict[str, Any]:
    """Change the name and/or note; streamed (``marker``, ``action: update``)."""
    fields = body.model_dump(exclude_none=True)
    if "name" in fields:
        fields["name"] = fields["name"].strip()
    return markers.edit_marker(state, marker_id, fields)


@router.delete(
    "/{marker_id}",
    status_code=204,
    summary="Remove a marker",
    dependencies=OPERATOR,
    responses={404: {"description": "no such marker"}},
)
def delete_marker(state: StateDep, marker_id: int = _MARKER_ID) -> Response:
    """Remove a marker and stream it (``marker``, ``action: delete``)."""
    markers.remove_marker(state, marker_id)
    return Response(status_code=204)


_CSV_COLUMNS = (
    "id",
    "name",
    "time_utc",
    "t_s",
    "longitude",
    "latitude",
    "h_m",
    "e_m",
    "n_m",
    "u_m",
    "mgrs",
    "utm",
    "note",
)


_XML_MIME = {"gpx": "application/gpx+xml", "kml": "application/vnd.google-earth.kml+xml"}


@router.get(
    "/export",
    summary="Markers as GeoJSON, CSV, GPX or KML",
    dependencies=READER,
    response_class=Response,
    responses={
        200: {
            "content": {
                "application/geo+json": {},
                "text/csv": {},
                "application/gpx+xml": {},
                "application/vnd.google-earth.kml+xml": {},
            }
        }
    },
)
def export_markers(
    state: StateDep,
    fmt: Literal["geojson", "csv", "gpx", "kml"] = Query("geojson", alias="format"),
) -> Response:
    """Every marker as GeoJSON, CSV, GPX waypoints or KML placemarks.

    GeoJSON ``[lon, lat, h]`` has h above the WGS84 ellipsoid; GPX ``<ele>`` and KML
    ``absolute`` are above the geoid where the site has a geoid model, as the file says.
    """
    if fmt in _XML_MIME:
        return Response(
            markers.markers_document(state, fmt),
            media_type=_XML_MIME[fmt],
            headers={"Content-Disposition": f'attachment; filename="markers.{fmt}"'},
        )
    if fmt == "geojson":
        import json

        text = json.dumps(markers.markers_geojson(state), indent=1)
        return Response(
            text,
            media_type="application/geo+json",
            headers={"Content-Disposition": 'attachment; filename="markers.geojson"'},
        )
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_CSV_COLUMNS)
    for m in markers.stored_markers(state):
        row = {**m, "longitude": m["lon_deg"], "latitude": m["lat_deg"]}
        if row.get("utm") is None:  # kept before markers recorded it
            row["utm"] = markers.utm_text_of(m["lat_deg"], m["lon_deg"]) or ""
        w.writerow([row[c] for c in _CSV_COLUMNS])
    return Response(
        buf.getvalue(),
        media_type="text/csv",
        headers={"Content-Disposition": 'attachment; filename="markers.csv"'},
    )
