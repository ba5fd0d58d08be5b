"""JSON responses encoded by msgspec, for large bodies that are already in their final shape.

A route that returns a plain dict or list has FastAPI validate it against the route's
``response_model`` (a pydantic model per point of every track) and serialise the
validated value again. For the bodies the console page polls (``/api/tracks``,
``/api/synopsis``, ``/api/detections``: thousands of points) that was a few per cent of
the server's CPU under a live replay, for values built from stored JSON that already
have exactly the model's keys. Such a route keeps ``response_model=`` (the OpenAPI
schema and docs) and returns :func:`json_response` instead, which FastAPI sends as it is.

The caller is responsible for what validation gave for free: the keys must be exactly
the model's (pydantic would have rejected extra keys of ``extra="forbid"`` models and
filled defaults), aliases applied (``"class"``, not ``cls``), and every value JSON-able.
The tests compare each such route with ``Model.model_validate(...)`` of the same data.

The body is encoded as every stored body is (:func:`~demtrack.server.store.codec.encode_json`,
msgspec): the JSON pydantic's ``dump_json`` writes for the same values, except that
integers stay integers where a model would have made them floats (``5`` rather than
``5.0``: the same JSON number) and NaN or infinities become ``null`` (the server's numbers
are finite by construction).
"""

from __future__ import annotations

from typing import Any

from starlette.responses import Response

from .store.codec import encode_json

__all__ = ["json_response"]


def json_response(content: Any, status_code: int = 200) -> Response:
    """An ``application/json`` response of ``content``, sent without FastAPI's validation.

    Parameters
    ----------
    content : Any
        The body, already holding exactly what the route's ``response_model`` would send
        (see the module docstring).
    status_code : int
        HTTP status.
    """
    return Response(encode_json(content), status_code=status_code, media_type="application/json")
