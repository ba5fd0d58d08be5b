"""Whose viser connection is whose: follow-session paths and the host put in URLs.

A console page is one operator's view: it makes up a session id and gives viser's client
(the 3D tab's iframe) the WebSocket URL ``ws://host:port/follow/<session>`` through
viser's own ``?websocket=`` URL parameter. The viser server accepts a WebSocket on any
path; the scene reads the path of each client's connection when it connects
(:func:`session_of_path` of :func:`websocket_path`), so every client of that page, and any
client it reconnects with, belongs to its session.

The session is also the page's ticket into the scene (:class:`SessionGate`): a console
page registers its session with its operator token (``PUT /api/scene3d/session``) before
its iframe connects, and the scene closes, before it sends anything, every WebSocket
whose path names no registered session. The scene's data (tracks, rays) is thus
reachable only with the operator token, as the console's, and the token itself never
goes into a URL. viser's page (its static client) holds no data and stays open, like the
console's own page.
"""

from __future__ import annotations

import collections
import logging
import re
import threading
from typing import Any

__all__ = [
    "CLOSE_UNAUTHORIZED",
    "FOLLOW_PATH",
    "SESSION_PATTERN",
    "SessionGate",
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
#: The WebSocket close code of a connection without a registered session (4000-4999 are
#: the application's; 4401 reads as HTTP's 401).
CLOSE_UNAUTHORIZED = 4401
_CLOSE_REASON = "operator token required: open the 3D view from the console"

log = logging.getLogger("demtrack.server")


class SessionGate:
    """The follow sessions admitted into the scene, and the check on each connection.

    Parameters
    ----------
    server : viser.ViserServer
        Whose WebSocket connections are checked.
    required : bool
        False admits every connection (a scene used without a console, in tests).
    max_sessions : int
        Sessions kept; the oldest registered are forgotten first.
    """

    def __init__(self, server: Any, *, required: bool = True, max_sessions: int = 1000) -> None:
        self.server = server
        self.required = required
        self.max_sessions = max_sessions
        self._sessions: collections.OrderedDict[str, None] = collections.OrderedDict()
        self._lock = threading.Lock()
        self.n_refused = 0
        # viser's own connect callbacks run only after a client's first camera message,
        # once the scene has been sent; those of its WebSocket server run before anything
        # is sent, so the check goes there.
        server._websock_server.on_client_connect(self._check)

    def admit(self, session: str) -> None:
        """Let the viser clients of ``session`` in (ValueError for a malformed id)."""
        if not _SESSION_RE.match(session):
            raise ValueError(f"bad follow session {session!r}: want {SESSION_PATTERN}")
        with self._lock:
            self._sessions[session] = None
            self._sessions.move_to_end(session)
            while len(self._sessions) > self.max_sessions:
                self._sessions.popitem(last=False)

    def admitted(self, session: str | None) -> bool:
        """Whether a connection on ``session`` may see the scene."""
        if not self.required:
            return True
        with self._lock:
            return session is not None and session in self._sessions

    async def _check(self, conn: Any) -> None:
        client_id = int(conn.client_id)
        session = session_of_path(websocket_path(self.server, client_id))
        if self.admitted(session):
            return
        self.n_refused += 1
        ws = self.server._websock_server._live_connections.get(client_id)
        if ws is not None:
            log.info("3D scene: refused a viser client without a registered session")
            await ws.close(CLOSE_UNAUTHORIZED, _CLOSE_REASON)


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
