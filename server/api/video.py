"""``/api/sensors/{id}/frame``, ``/api/frames``: cameras' newest video frames, in and out.

Thin: the logic is :mod:`demtrack.server.video.frames_http`, the frames are held by the
app's :class:`~demtrack.server.video.frame_book.FrameBook`.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Request
from starlette.responses import Response

from ..video.frame_book import FrameBook
from ..video.frames_http import frame_book, frame_index, frame_response, put_frame
from .deps import OPERATOR, READER, StateDep
from .errors import error_responses

__all__ = ["router"]

router = APIRouter(tags=["video"])


async def _book(request: Request, state: StateDep) -> FrameBook:
    """The app's frame book (``state`` first: the server has started)."""
    return frame_book(request.app.state)


BookDep = Annotated[FrameBook, Depends(_book)]


@router.put(
    "/api/sensors/{sensor_id}/frame",
    dependencies=OPERATOR,
    responses=error_responses(401, 404, 413, 422),
    summary="Post the camera's newest video frame (JPEG)",
    openapi_extra={
        "requestBody": {"required": True, "content": {"image/jpeg": {"schema": {}}}},
    },
)
async def put_sensor_frame(
    sensor_id: str,
    request: Request,
    book: BookDep,
    content_type: Annotated[str | None, Header()] = None,
    x_frame_time: Annotated[
        str | None,
        Header(description="capture time: ISO 8601 with a zone, or UNIX seconds UTC"),
    ] = None,
    x_frame_boxes: Annotated[
        str | None, Header(description="JSON list of [u_min, v_min, u_max, v_max] (px)")
    ] = None,
) -> dict[str, Any]:
    """Keep this JPEG as the sensor's newest frame (one per sensor, in memory).

    The body is the JPEG itself. A frame older than the one held is acknowledged with
    ``stored: false``. Needs the operator token; 404 for a sensor the site does not have;
    422 for a body that is not a complete JPEG or a missing ``X-Frame-Time``.
    """
    body = await request.body()
    return put_frame(book, sensor_id, body, content_type, x_frame_time, x_frame_boxes)


@router.get(
    "/api/sensors/{sensor_id}/frame.jpg",
    dependencies=READER,
    response_class=Response,
    responses={
        **error_responses(401, 404),
        200: {"content": {"image/jpeg": {}}, "description": "the newest frame"},
        304: {"description": "unchanged since the If-None-Match tag"},
    },
    summary="The camera's newest video frame",
)
async def get_sensor_frame(
    sensor_id: str,
    book: BookDep,
    if_none_match: Annotated[str | None, Header()] = None,
) -> Response:
    """The newest frame (``Cache-Control: no-store``), with ``ETag`` and ``X-Frame-Time``.

    Poll with ``If-None-Match: <the ETag>``: 304 with no body while unchanged. 404 while the
    server has no frame of that sensor (the console shows the still).
    """
    return frame_response(book, sensor_id, if_none_match)


@router.get(
    "/api/frames",
    dependencies=READER,
    response_class=Response,
    responses={
        **error_responses(401),
        200: {"content": {"application/json": {}}, "description": "each camera's newest frame"},
        304: {"description": "no frame changed since the If-None-Match tag"},
    },
    summary="Which cameras have live frames, and their tags",
)
async def list_frames(
    book: BookDep, if_none_match: Annotated[str | None, Header()] = None
) -> Response:
    """Each camera's newest frame: its ``etag``, ``t_s`` and ``time_utc``, pixel size.

    One poll for every camera (the console's): 304 with no body while no frame changed;
    then only the cameras whose tag changed need their ``frame.jpg``.
    """
    return frame_index(book, if_none_match)
