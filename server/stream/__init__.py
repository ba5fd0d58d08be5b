"""The live WebSocket stream ``/ws``: its endpoint (:mod:`.endpoint`).

Fans the hub's messages out to clients, resumes them from the store with ``?since=N``
and answers their pings. May import ``server.hub``, ``server.messages``, the store,
``server.security`` and ``server.state``; nothing in ``server.api`` imports it.
"""

from __future__ import annotations

from .endpoint import router

__all__ = ["router"]
