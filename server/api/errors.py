"""Errors to HTTP responses, by exception class, in one place.

:data:`STATUS_BY_ERROR` maps the engine's exception classes to statuses; the most
specific class in an exception's MRO wins (``UnknownSensorError`` is a ``NotFoundError``
before it is a ``SiteError``). Every answer is ``{"detail": "<the message>"}``; a request
that fails validation also gets ``errors`` (each ``loc``, ``msg``, ``type``, without the
offending input, which may be NaN or large).
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from demtrack.core.errors import DemtrackError, NotFoundError

__all__ = ["STATUS_BY_ERROR", "install_error_handlers", "status_for", "validation_detail"]

#: HTTP status of each engine exception class (subclasses inherit theirs).
STATUS_BY_ERROR: dict[type[Exception], int] = {
    NotFoundError: 404,  # an unknown sensor, track, ...
    DemtrackError: 422,  # everything else the client's input caused
}


def status_for(exc: Exception) -> int:
    """The status of ``exc``: that of the first class of its MRO in the map (else 500)."""
    for cls in type(exc).__mro__:
        if cls in STATUS_BY_ERROR:
            return STATUS_BY_ERROR[cls]
    return 500


def validation_detail(errors: list[dict[str, Any]]) -> tuple[str, list[dict[str, Any]]]:
    """One readable line, and the errors without the offending input (NaN, or large)."""
    clean, parts = [], []
    for e in errors:
        loc = [str(x) for x in e.get("loc", ())]
        msg = str(e.get("msg", "invalid"))
        clean.append({"loc": loc, "msg": msg, "type": str(e.get("type", ""))})
        parts.append(f"{'.'.join(loc)}: {msg}" if loc else msg)
    shown = "; ".join(parts[:5]) + (f" (and {len(parts) - 5} more)" if len(parts) > 5 else "")
    return shown, jsonable_encoder(clean)


async def _on_validation(request: Request, exc: RequestValidationError) -> JSONResponse:
    detail, errors = validation_detail(list(exc.errors()))
    return JSONResponse({"detail": detail, "errors": errors}, status_code=422)


async def _on_engine_error(request: Request, exc: Exception) -> JSONResponse:
    return JSONResponse({"detail": str(exc)}, status_code=status_for(exc))


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers: request validation, then each class of the map."""
    app.add_exception_handler(RequestValidationError, _on_validation)  # type: ignore[arg-type]
    for cls in STATUS_BY_ERROR:
        app.add_exception_handler(cls, _on_engine_error)
