"""Errors to HTTP responses, by exception class, in one place.

:data:`STATUS_BY_ERROR` maps the engine's exception classes to statuses; the most
specific class in an exception's MRO wins (``UnknownSensorError`` is a ``NotFoundError``
before it is a ``SiteError``). Every answer is ``{"detail": "<the message>"}``; a request
that fails validation also gets ``errors`` (each ``loc``, ``msg``, ``type``, without the
offending input, which may be NaN or large).

A body that is not what the route takes says so in words, not in pydantic's terms: a
bare list where an object is expected gives ``request body: expected a JSON object with a
'detections' list, got a list``; broken JSON gives the decoder's message with its line,
column and character position.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response

from demtrack.core.errors import DemtrackError, NotFoundError

from ..store.integrity import StoreFullError, StoreLostError, StoreUnreachableError

__all__ = [
    "STATUS_BY_ERROR",
    "ErrorOut",
    "ValidationErrorOut",
    "error_responses",
    "expected_body",
    "install_error_handlers",
    "status_for",
    "validation_detail",
]

#: HTTP status of each engine exception class (subclasses inherit theirs).
STATUS_BY_ERROR: dict[type[Exception], int] = {
    NotFoundError: 404,  # an unknown sensor, track, ...
    StoreFullError: 507,  # the disk is full: the write was refused, reads go on
    StoreLostError: 503,  # the database file was deleted or replaced while running
    StoreUnreachableError: 503,  # the PostgreSQL server went away: nothing was stored
    DemtrackError: 422,  # everything else the client's input caused
}


class ErrorOut(BaseModel):
    """Every error answer: one line saying what is wrong."""

    detail: str


class ValidationIssueOut(BaseModel):
    """One failed check of a request (without the offending input)."""

    loc: list[str]
    msg: str
    type: str


class ValidationErrorOut(BaseModel):
    """A request the server cannot use: the line, and each failed check when validated."""

    detail: str
    errors: list[ValidationIssueOut] = []


_ERROR_TEXT = {
    400: "a request the server cannot read",
    401: "no operator token, or the wrong one",
    404: "no such sensor, track or file",
    413: "the body or the batch is larger than the server's limit",
    422: "a request that fails validation (parameters or body), or that the engine refuses",
    503: "the database file was lost while the server ran: nothing more is stored",
    507: "the disk is full: the batch was not stored (reads go on)",
}


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses=`` for these error statuses, each ``{"detail": "..."}``.

    422 is :class:`ValidationErrorOut` (also with ``errors``); it replaces FastAPI's own
    422 schema, which is not what :func:`install_error_handlers` sends.
    """
    return {
        code: {
            "model": ValidationErrorOut if code == 422 else ErrorOut,
            "description": _ERROR_TEXT.get(code, "error"),
        }
        for code in codes
    }


_OBJECT_TYPES = {"model_attributes_type", "dict_type", "model_type"}
_JSON_KIND = {
    "array": "list",
    "object": "object",
    "string": "string",
    "number": "number",
    "integer": "integer",
    "boolean": "boolean",
}


def status_for(exc: Exception) -> int:
    """The status of ``exc``: that of the first class of its MRO in the map (else 500)."""
    for cls in type(exc).__mro__:
        if cls in STATUS_BY_ERROR:
            return STATUS_BY_ERROR[cls]
    return 500


def _json_kind(value: Any) -> str:
    """What a decoded JSON value is, in words (``a list``, ``a string``, ``null``)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, (list, tuple)):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _field_kind(prop: dict[str, Any]) -> str:
    kinds = [p.get("type") for p in prop.get("anyOf", [prop])]
    names = [_JSON_KIND.get(str(k), "value") for k in kinds if k and k != "null"]
    return " or ".join(dict.fromkeys(names)) or "value"


def expected_body(model: type[BaseModel] | None) -> str:
    """``expected a JSON object with a 'detections' list`` for a body model's required fields."""
    if model is None:
        return "expected a JSON object"
    schema = model.model_json_schema(by_alias=True)
    props: dict[str, Any] = schema.get("properties", {})
    parts = []
    for name in schema.get("required", []):
        kind = _field_kind(props.get(name, {}))
        article = "an" if kind[:1] in "aeiou" else "a"
        parts.append(f"{article} {name!r} {kind}")
    if not parts:
        return "expected a JSON object"
    listed = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
    return f"expected a JSON object with {listed}"


def _body_model(request: Request | None) -> type[BaseModel] | None:
    """The pydantic model of the route's body, if it takes exactly one."""
    if request is None:
        return None
    dependant = getattr(request.scope.get("route"), "dependant", None)
    params = list(getattr(dependant, "body_params", None) or [])
    if len(params) != 1:
        return None
    annotation = getattr(params[0].field_info, "annotation", None)
    return (
        annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None
    )


def _json_error(e: dict[str, Any], doc: Any) -> str:
    loc = list(e.get("loc", ()))
    pos = loc[1] if len(loc) > 1 and isinstance(loc[1], int) else None
    reason = str((e.get("ctx") or {}).get("error") or "invalid JSON")
    if pos is None:
        return f"request body is not valid JSON: {reason}"
    if isinstance(doc, (bytes, bytearray)):
        doc = bytes(doc).decode("utf-8", "replace")
    if isinstance(doc, str):
        line = doc.count("\n", 0, pos) + 1
        column = pos - (doc.rfind("\n", 0, pos) + 1) + 1
        return (
            f"request body is not valid JSON: {reason} at line {line} column {column}"
            f" (character {pos})"
        )
    return f"request body is not valid JSON: {reason} at character {pos}"


def _message(e: dict[str, Any], model: type[BaseModel] | None, doc: Any) -> str:
    loc = [str(x) for x in e.get("loc", ())]
    kind = str(e.get("type", ""))
    msg = str(e.get("msg", "invalid"))
    if kind == "json_invalid":
        return _json_error(e, doc)
    if loc == ["body"] and kind in _OBJECT_TYPES:
        return f"request body: {expected_body(model)}, got {_json_kind(e.get('input'))}"
    if loc == ["body"] and kind == "missing":
        return f"request body is missing: {expected_body(model)}"
    return f"{'.'.join(loc)}: {msg}" if loc else msg


def validation_detail(
    errors: list[dict[str, Any]],
    model: type[BaseModel] | None = None,
    body: Any = None,
) -> tuple[str, list[dict[str, Any]]]:
    """One readable line, and the errors without the offending input (NaN, or large).

    ``model`` (the route's body model) and ``body`` (the raw body, for a JSON decode
    error's line and column) make body-level errors say what was expected.
    """
    clean, parts = [], []
    for e in errors:
        loc = [str(x) for x in e.get("loc", ())]
        clean.append(
            {"loc": loc, "msg": str(e.get("msg", "invalid")), "type": str(e.get("type", ""))}
        )
        parts.append(_message(e, model, body))
    shown = "; ".join(parts[:5]) + (f" (and {len(parts) - 5} more)" if len(parts) > 5 else "")
    return shown, jsonable_encoder(clean)


async def _on_validation(request: Request, exc: RequestValidationError) -> JSONResponse:
    detail, errors = validation_detail(
        list(exc.errors()), _body_model(request), getattr(exc, "body", None)
    )
    return JSONResponse({"detail": detail, "errors": errors}, status_code=422)


_UNPARSED = "There was an error parsing the body"  # FastAPI's words, for any failure


async def _on_http_error(request: Request, exc: StarletteHTTPException) -> Response:
    """FastAPI's handler, except a body it could not decode: 422, saying why, in one line.

    FastAPI answers 400 "There was an error parsing the body" for a body that is not
    UTF-8 (and for other read failures); the cause is what the client needs to know.
    """
    if exc.status_code == 400 and exc.detail == _UNPARSED:
        cause = exc.__cause__
        if isinstance(cause, UnicodeDecodeError):
            why = f"not UTF-8 text ({cause.reason} at byte {cause.start})"
        else:
            why = (
                str(cause).strip().splitlines()[0] if cause and str(cause).strip() else "unreadable"
            )
        return JSONResponse({"detail": f"request body is not valid JSON: {why}"}, status_code=422)
    return await http_exception_handler(request, exc)


async def _on_engine_error(request: Request, exc: Exception) -> JSONResponse:
    return JSONResponse({"detail": str(exc)}, status_code=status_for(exc))


def install_error_handlers(app: FastAPI) -> None:
    """Register the handlers: request validation, then each class of the map."""
    app.add_exception_handler(RequestValidationError, _on_validation)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, _on_http_error)  # type: ignore[arg-type]
    for cls in STATUS_BY_ERROR:
        app.add_exception_handler(cls, _on_engine_error)
