"""Whose viser connection is whose: follow-session paths and the host put in URLs.

A console page is one operator's view: it makes up a session id and gives viser's client
(the 3D tab's iframe) the WebSocket URL ``ws://host:port/follow/<session>`` through
viser's own ``?websocket=`` URL parameter. The viser server accepts a WebSocket on any
path; the scene reads the path of each client's connection when it connects
(:func:`session_of_path` of :func:`websocket_path`), so every client of that page, and any
client it reconnects with, belongs to its session.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = [
    "FOLLOW_PATH",
    "SESSION_PATTERN",
    "display_host",
    "session_of_path",
    "websocket_path",
]

#: A follow session id (made up by a console page): URL-safe, 8 to 64 characters.
SESSION_PATTERN = r"^[A-Za-z0-9_-]{8,64}$"
#: The WebSocket path prefix a viser client joins a follow session with:
#: ``ws://host:port/follow/<session>``.
FOLLOW_PATH = "/follow/"
_SESSION_RE = re.compile(SESSION_PATTERN)


def session_of_path(path: str | None) -> str | None:
    """The follow session a viser client's WebSocket request path names.

    Parameters
    ----------
    path : str or None
        The request target, e.g. ``/follow/abcd1234?x=1`` (the query is ignored).

    Returns
    -------
    str or None
        The session id, or None for any other path (``/``, a malformed id).
    """
    if not path:
        return None
    p = path.partition("?")[0]
    if not p.startswith(FOLLOW_PATH):
        return None
    sid = p[len(FOLLOW_PATH) :].rstrip("/")
    return sid if _SESSION_RE.match(sid) else None


def websocket_path(server: Any, client_id: int) -> str | None:
    """The request path of a viser client's WebSocket (None if it cannot be read).

    viser 1.1 keeps each live ``websockets`` connection in its WebSocket server's
    ``_live_connections`` (from before its connect callbacks run until after its
    disconnect callbacks); this is the one private attribute the scene reads, and
    ``tests/server/test_scene3d.py`` fails if a viser upgrade moves it.

    Parameters
    ----------
    server : viser.ViserServer
    client_id : int
        The client's id, as its connect callback gives it.

    Returns
    -------
    str or None
    """
    try:
        conn = server._websock_server._live_connections[client_id]
        return str(conn.request.path)
    except (AttributeError, KeyError, TypeError):
        return None


def display_host(host: str) -> str:
    """The host to put in URLs for a bind address (a wildcard becomes 127.0.0.1)."""
    if host in ("", "0.0.0.0", "::", "[::]"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host and not host.startswith("[") else host
