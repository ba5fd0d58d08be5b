"""Operator token: resolution at start-up and the request checks.

The token is taken from the settings, else from ``<db>.token`` (written 0600 on first
start with a fresh random token). Requests present it as ``Authorization: Bearer T``,
``X-Demtrack-Token: T`` or ``?token=T`` (browsers cannot set headers on a WebSocket or
an ``<img>``). Comparison is constant-time.
"""

from __future__ import annotations

import hmac
import os
import secrets
from pathlib import Path

from fastapi import HTTPException, Request, WebSocket, status

from .settings import Settings

__all__ = ["presented_token", "require_operator", "require_reader", "resolve_token", "token_ok"]


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


def require_operator(request: Request) -> None:
    """Dependency of every write endpoint: 401 without the operator token."""
    if not token_ok(request):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "operator token required (Authorization: Bearer <token>)",
            headers={"WWW-Authenticate": "Bearer"},
        )


def require_reader(request: Request) -> None:
    """Dependency of the read-only endpoints: open when ``open_reads`` is set."""
    if not request.app.state.settings.open_reads:
        require_operator(request)
