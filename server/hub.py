"""WebSocket fan-out: one bounded queue per client, publishing never waits.

The pipeline publishes from worker threads (:meth:`Hub.publish_threadsafe`); messages are
serialised once and handed to every client's queue on the event loop, in sequence order
(``call_soon_threadsafe`` runs callbacks in the order they were scheduled). A client whose
queue is full is dropped (closed with code 1013, "try again later") instead of slowing
the others; it reconnects with ``?since=N`` and gets what it missed from the event log.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from .db import dumps_json

__all__ = ["Client", "Hub", "OVERFLOW"]

#: Put in a client's queue when it overflowed: its sender closes the connection.
OVERFLOW = (-1, "")


@dataclass(eq=False)
class Client:
    """One connection's outbound queue of ``(seq, json_text)``."""

    queue: asyncio.Queue[tuple[int, str]]
    last_sent: int = 0
    overflowed: bool = False
    send_lock: asyncio.Lock = field(default_factory=asyncio.Lock)


class Hub:
    """The set of connected clients.

    Parameters
    ----------
    queue_size : int
        Messages buffered per client.
    """

    def __init__(self, queue_size: int) -> None:
        self.queue_size = queue_size
        self.clients: set[Client] = set()
        self.last_seq = 0
        self.n_dropped = 0
        self._loop: asyncio.AbstractEventLoop | None = None

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        """Remember the event loop that owns the clients."""
        self._loop = loop

    def register(self) -> Client:
        """A new client (call on the event loop)."""
        client = Client(asyncio.Queue(self.queue_size))
        self.clients.add(client)
        return client

    def unregister(self, client: Client) -> None:
        """Forget ``client``."""
        self.clients.discard(client)

    def publish(self, messages: list[dict[str, Any]]) -> None:
        """Queue messages (dicts with ``seq``) for every client; on the event loop."""
        encoded = [(int(m["seq"]), dumps_json(m)) for m in messages]
        if encoded:
            self.last_seq = max(self.last_seq, encoded[-1][0])
        for client in list(self.clients):
            if client.overflowed:
                continue
            for item in encoded:
                try:
                    client.queue.put_nowait(item)
                except asyncio.QueueFull:
                    self._overflow(client)
                    break

    def _overflow(self, client: Client) -> None:
        client.overflowed = True
        self.n_dropped += 1
        while not client.queue.empty():
            client.queue.get_nowait()
        client.queue.put_nowait(OVERFLOW)

    def publish_threadsafe(self, messages: list[dict[str, Any]]) -> None:
        """:meth:`publish` from any thread (no-op before :meth:`bind`)."""
        if messages and self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self.publish, messages)
