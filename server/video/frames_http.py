"""The logic of the frame endpoints (the router is :mod:`demtrack.server.api.video`).

``PUT /api/sensors/{id}/frame``: the body is one JPEG (``Content-Type: image/jpeg``),
``X-Frame-Time`` its capture time (ISO 8601 with a zone, or UNIX seconds), optionally
``X-Frame-Boxes`` the JSON list of the detections' boxes in that frame. ``GET
/api/sensors/{id}/frame.jpg``: the newest frame with ``Cache-Control: no-store``, its
``ETag``, ``X-Frame-Time`` (ISO, milliseconds, UTC) and ``X-Frame-Time-S`` (UNIX
seconds); ``If-None-Match`` with that tag answers 304 with no body; 404 while the
server holds no frame of that sensor. ``GET /api/frames``: every camera's newest frame's
tag and time in one small answer (the console polls it, then fetches only the frames that
changed), 304 while nothing changed.
"""

from __future__ import annotations

import json
import threading
from typing import Any

from starlette.responses import Response

from demtrack.core.errors import NotFoundError, TimeFormatError, VideoError
from demtrack.core.io.times import format_utc, parse_time_value

from .frame_book import FrameBook, StoredFrame

__all__ = ["frame_book", "frame_index", "frame_response", "put_frame"]

_BOOK_LOCK = threading.Lock()


def frame_book(app_state: Any) -> FrameBook:
    """The app's frame book (``app.state.frame_book``), made on first use."""
    book = getattr(app_state, "frame_book", None)
    if book is not None:
        return book
    with _BOOK_LOCK:
        book = getattr(app_state, "frame_book", None)
        if book is None:
            console = app_state.console
            book = FrameBook(list(console.site.sensors), max_bytes=console.settings.max_frame_bytes)
            app_state.frame_book = book
    return book


def put_frame(
    book: FrameBook,
    sensor: str,
    body: bytes,
    content_type: str | None,
    time_header: str | None,
    boxes_header: str | None,
) -> dict[str, Any]:
    """Store one posted frame; the acknowledgement.

    Raises
    ------
    NotFoundError
        An unknown sensor (404).
    VideoError, TimeFormatError
        A body that is not a JPEG, a missing or bad ``X-Frame-Time``, bad boxes (422).
    """
    if sensor not in book.sensors:
        raise NotFoundError(f"unknown sensor {sensor!r}")
    media = (content_type or "").split(";")[0].strip().lower()
    if media not in ("image/jpeg", "image/jpg"):
        raise VideoError(f"frame Content-Type must be image/jpeg, got {content_type or 'none'!r}")
    if time_header is None or not time_header.strip():
        raise TimeFormatError(
            "X-Frame-Time header required: the frame's capture time, ISO 8601 with a zone"
            " or UNIX seconds"
        )
    t_s = parse_time_value(time_header, "X-Frame-Time")
    boxes = None
    if boxes_header:
        try:
            boxes = json.loads(boxes_header)
        except ValueError as exc:
            raise VideoError(f"X-Frame-Boxes is not JSON: {exc}") from None
        if not isinstance(boxes, list):
            raise VideoError("X-Frame-Boxes must be a JSON list of [u_min, v_min, u_max, v_max]")
    stored = book.put(sensor, body, t_s, boxes)
    if stored is None:
        held = book.get(sensor)
        newer = "" if held is None else f" ({format_utc(held.t_s)})"
        return {"stored": False, "reason": f"older than the frame held{newer}"}
    return {
        "stored": True,
        "sensor": sensor,
        "t_s": stored.t_s,
        "time_utc": format_utc(stored.t_s),
        "width": stored.width,
        "height": stored.height,
        "bytes": len(stored.jpeg),
        "etag": stored.etag,
    }


def _headers(frame: StoredFrame) -> dict[str, str]:
    h = {
        "Cache-Control": "no-store",
        "ETag": frame.etag,
        "X-Frame-Time": format_utc(frame.t_s),
        "X-Frame-Time-S": repr(frame.t_s),
    }
    if frame.boxes is not None:
        h["X-Frame-Boxes"] = json.dumps([list(b) for b in frame.boxes])
    return h


def _matches(if_none_match: str | None, etag: str) -> bool:
    if not if_none_match:
        return False
    tags = [t.strip() for t in if_none_match.split(",")]
    return "*" in tags or etag in tags or f"W/{etag}" in tags


def frame_response(book: FrameBook, sensor: str, if_none_match: str | None) -> Response:
    """The newest frame (200), unchanged (304), or 404.

    Raises
    ------
    NotFoundError
        An unknown sensor, or no frame held for it yet.
    """
    if sensor not in book.sensors:
        raise NotFoundError(f"unknown sensor {sensor!r}")
    frame = book.get(sensor)
    if frame is None:
        raise NotFoundError(f"no video frame from {sensor} yet")
    if _matches(if_none_match, frame.etag):
        return Response(status_code=304, headers=_headers(frame))
    return Response(frame.jpeg, media_type="image/jpeg", headers=_headers(frame))


def frame_index(book: FrameBook, if_none_match: str | None) -> Response:
    """``{"frames": {sensor: {"etag", "t_s", "time_utc", "width", "height"}}}`` or 304."""
    version, frames = book.index()
    headers = {"Cache-Control": "no-store", "ETag": version}
    if _matches(if_none_match, version):
        return Response(status_code=304, headers=headers)
    body = {
        "frames": {
            s: {
                "etag": f.etag,
                "t_s": f.t_s,
                "time_utc": format_utc(f.t_s),
                "width": f.width,
                "height": f.height,
            }
            for s, f in sorted(frames.items())
        }
    }
    return Response(json.dumps(body), media_type="application/json", headers=headers)
