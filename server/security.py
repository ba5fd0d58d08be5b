"""Operator token: resolution at start-up, the request checks, and keeping it out of logs.

The token is taken from the settings, else from ``<db>.token`` (written 0600 on first
start with a fresh random token). Requests present it as ``Authorization: Bearer T``,
``X-Demtrack-Token: T`` or ``?token=T`` (browsers cannot set headers on a WebSocket or
an ``<img>``). Comparison is constant-time.

The OpenAPI document declares it as the ``operatorToken`` HTTP bearer scheme
(:data:`BEARER`), so ``/docs`` can send it. :class:`RequestGate` checks it before a
protected route's body is read, and enforces the body size limit with a message naming
the limit. :func:`install_log_redaction` keeps ``?token=...`` out of uvicorn's logs.
"""

from __future__ import annotations

import hmac
import logging
import os
import re
import secrets
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Request, WebSocket, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.routing import compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .json_response import json_response
from .settings import Settings

__all__ = [
    "BEARER",
    "TOKEN_REQUIRED",
    "RequestGate",
    "TokenRedactor",
    "install_log_redaction",
    "presented_token",
    "protected_routes",
    "redact",
    "require_operator",
    "require_reader",
    "resolve_token",
    "token_ok",
]

#: The one-line answer to a request without the token.
TOKEN_REQUIRED = "operator token required (Authorization: Bearer <token>)"

#: The operator token as an OpenAPI security scheme (the check itself is :func:`token_ok`).
BEARER = HTTPBearer(
    auto_error=False,
    scheme_name="operatorToken",
    description="The operator token (printed by `demtrack serve`, or in `<db>.token`);"
    " also accepted as `X-Demtrack-Token: <token>` or `?token=<token>`.",
)
_Credentials = Annotated[HTTPAuthorizationCredentials | None, Depends(BEARER)]


def resolve_token(settings: Settings) -> tuple[str, Path | None, bool]:
    """The operator token, its file (None if configured) and whether it was generated now."""
    if settings.token is not None and settings.token.get_secret_value():
        return settings.token.get_secret_value(), None, False
    path = settings.resolved_db_path.with_name(settings.resolved_db_path.name + ".token")
    if path.is_file():
        text = path.read_text(encoding="utf-8").strip()
        if text:
            return text, path, False
    token = secrets.token_urlsafe(32)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(token + "\n")
    return token, path, True


def presented_token(conn: Request | WebSocket) -> str | None:
    """The token a request or WebSocket handshake carries, if any."""
    auth = conn.headers.get("authorization", "")
    if auth[:7].lower() == "bearer ":
        return auth[7:].strip()
    return conn.headers.get("x-demtrack-token") or conn.query_params.get("token")


def token_ok(conn: Request | WebSocket) -> bool:
    """Whether ``conn`` carries the operator token."""
    given = presented_token(conn)
    want: str = conn.app.state.token
    return given is not None and hmac.compare_digest(given.encode(), want.encode())


def _unauthorized() -> HTTPException:
    return HTTPException(
        status.HTTP_401_UNAUTHORIZED, TOKEN_REQUIRED, headers={"WWW-Authenticate": "Bearer"}
    )


async def require_operator(request: Request, _credentials: _Credentials = None) -> None:
    """Dependency of every write endpoint: 401 without the operator token.

    ``async`` (as :func:`require_reader`): FastAPI runs a plain ``def`` dependency in a
    worker thread, where it would queue behind expensive reads.
    """
    if not token_ok(request):
        raise _unauthorized()


async def require_reader(request: Request, _credentials: _Credentials = None) -> None:
    """Dependency of the read-only endpoints: open when ``open_reads`` is set."""
    if not request.app.state.settings.open_reads:
        await require_operator(request)


# ------------------------------------------------------------------- the gate
def _calls(dependant: Any) -> set[Any]:
    out: set[Any] = set()
    for dep in getattr(dependant, "dependencies", ()):
        out.add(dep.call)
        out |= _calls(dep)
    return out


def _route_level(route: Any) -> str | None:
    """``"operator"``, ``"reader"`` or None: what the route's dependencies demand."""
    calls = _calls(getattr(route, "dependant", None))
    if require_operator in calls:
        return "operator"
    if require_reader in calls:
        return "reader"
    return None


def _route_contexts(app: Any) -> list[Any]:
    """Every HTTP route of ``app`` with its full path and its dependencies.

    FastAPI 0.165 keeps an included router as one entry of ``app.routes``;
    ``fastapi.routing.iter_route_contexts`` (what its OpenAPI builder walks) lists the
    routes inside with the router's prefix and dependencies applied.
    """
    try:
        from fastapi.routing import iter_route_contexts
    except ImportError:  # an older FastAPI: the routes are flat
        return list(app.routes)
    return list(iter_route_contexts(app.routes))


def protected_routes(app: Any) -> list[tuple[re.Pattern[str], frozenset[str], str]]:
    """``(path regex, methods, level)`` of each route that demands the token."""
    out = []
    for route in _route_contexts(app):
        path, methods = getattr(route, "path", None), getattr(route, "methods", None)
        if not path or not methods:
            continue
        try:
            level = _route_level(route)
        except AttributeError:
            continue
        if level is not None:
            methods = set(methods) | ({"HEAD"} if "GET" in methods else set())
            out.append((compile_path(path)[0], frozenset(methods), level))
    return out


class RequestGate:
    """ASGI middleware: the token before the body, and the body size limit.

    FastAPI reads and parses a request's body before it runs the route's dependencies, so
    without this a client without the token could make the server parse a body of up to
    ``max_body_bytes``. The gate finds the route (:func:`protected_routes`, listed once)
    and, when its dependencies demand the token (:func:`require_operator`, or
    :func:`require_reader` with reads closed), answers 401 before anything is read. A
    declared or streamed body over ``max_body_bytes`` gets 413 with the limit named.
    """

    def __init__(self, app: ASGIApp, max_body_bytes: int) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes
        self._routes: list[tuple[re.Pattern[str], frozenset[str], str]] | None = None

    def _level(self, scope: Scope) -> str | None:
        fastapi_app = scope.get("app")
        if fastapi_app is None:
            return None
        if self._routes is None:  # the routes are all included before the first request
            self._routes = protected_routes(fastapi_app)
        path, method = scope.get("path", ""), scope.get("method", "GET")
        root = scope.get("root_path", "")
        if root and path.startswith(root):  # routes match below the mount point
            path = path[len(root) :]
        for regex, methods, level in self._routes:
            if method in methods and regex.match(path):
                return level
        return None

    def _too_large(self, size: str) -> str:
        return (
            f"request body {size} is larger than the limit of {self.max_body_bytes} bytes"
            " (DEMTRACK_MAX_BODY_BYTES); send smaller batches"
        )

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Answer 401 or 413 without calling the app, or call it with a counted body."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        level = self._level(scope)
        if level is not None:
            request = Request(scope)
            needed = level == "operator" or not request.app.state.settings.open_reads
            if needed and not token_ok(request):
                response = json_response({"detail": TOKEN_REQUIRED}, status_code=401)
                response.headers["WWW-Authenticate"] = "Bearer"
                await response(scope, receive, send)
                return
        declared = _content_length(scope)
        if declared is not None and declared > self.max_body_bytes:
            detail = self._too_large(f"of {declared} bytes")
            await json_response({"detail": detail}, status_code=413)(scope, receive, send)
            return
        seen = 0

        async def limited() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body_bytes:
                    # FastAPI re-raises an HTTPException met while reading the body.
                    raise HTTPException(413, self._too_large(f"of over {seen} bytes"))
            return message

        await self.app(scope, limited, send)


def _content_length(scope: Scope) -> int | None:
    for key, value in scope.get("headers", ()):
        if key == b"content-length":
            try:
                return int(value)
            except ValueError:
                return None
    return None


# ------------------------------------------------------------------- the logs
_TOKEN_IN_TEXT = re.compile(r"(?i)((?:[?&]|%3F|%26)token(?:=|%3D))[^&\s\"']*")


def redact(text: str) -> str:
    """``text`` with every ``token=<value>`` query parameter's value replaced by ``***``."""
    return _TOKEN_IN_TEXT.sub(r"\1***", text)


class TokenRedactor(logging.Filter):
    """A logging filter that removes ``?token=...`` values from a record's message."""

    def filter(self, record: logging.LogRecord) -> bool:  # noqa: D102 - logging.Filter's
        if isinstance(record.msg, str) and "token" in record.msg.lower():
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {
                k: redact(v) if isinstance(v, str) else v for k, v in record.args.items()
            }
        return True


_REDACTED_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.access", "demtrack.server")


def install_log_redaction() -> None:
    """Add :class:`TokenRedactor` to uvicorn's loggers and ours (once each).

    uvicorn logs each WebSocket handshake (``"WebSocket /ws?token=..." [accepted]``, on
    ``uvicorn.error``) and each request line with its query (``uvicorn.access``). A filter
    on a logger sees only records logged on that logger itself, so each is named. Call it
    after uvicorn has configured logging (``uvicorn.Config`` does so when built); it is
    also called by :func:`~demtrack.server.app.create_app`.
    """
    for name in _REDACTED_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, TokenRedactor) for f in logger.filters):
            logger.addFilter(TokenRedactor())
