"""WebSocket fan-out: one bounded queue per client, publishing never waits.

The pipeline publishes from worker threads (:meth:`Hub.publish_threadsafe`); messages are
serialised once and handed to every client's queue on the event loop, in sequence order
(``call_soon_threadsafe`` runs callbacks in the order they were scheduled). A client whose
queue is full is dropped (closed with code 1013, "try again later") instead of slowing
the others; it reconnects with ``?since=N`` and gets what it missed from the event log.

A client that opted in (``/ws?batch=1``) is sent, whenever its queue holds several
messages, one ``batch`` frame carrying them in order (:func:`take`, :func:`pack`): the
envelope is joined from the already-encoded texts, never re-encoded.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from .messages import BATCH_MAX_MESSAGES as _BATCH_MAX
from .store.codec import dumps_json

__all__ = [
    "BATCH_MAX_CHARS",
    "BATCH_MAX_MESSAGES",
    "Client",
    "Hub",
    "OVERFLOW",
    "StreamMessage",
    "batch_text",
    "encoded",
    "pack",
    "take",
]

#: Put in a client's queue when it overflowed: its sender closes the connection.
OVERFLOW = (-1, "")
#: At most this many messages in one ``batch`` frame (its schema says so too).
BATCH_MAX_MESSAGES = _BATCH_MAX
#: A ``batch`` frame stops growing once its messages hold this many characters.
BATCH_MAX_CHARS = 1_000_000
_BATCH_HEAD = '{"type":"batch","seq":null,"messages":['


class StreamMessage(dict):  # type: ignore[type-arg]
    """A published message: the payload with its ``seq`` (last), carrying its JSON text.

    The pipeline makes these from what the store wrote (:func:`~demtrack.server.store.codec.
    published_text`), so the hub queues ``text`` without encoding the message again;
    subscribers that read the dict (the 3D scene) see an ordinary message.
    """

    __slots__ = ("text",)

    def __init__(self, payload: dict[str, Any], seq: int, text: str) -> None:
        super().__init__(payload)
        self["seq"] = seq
        self.text = text


def encoded(message: dict[str, Any]) -> str:
    """A message's JSON text: its own when it carries one, else ``dumps_json``."""
    return message.text if isinstance(message, StreamMessage) else dumps_json(message)


@dataclass(eq=False)
class Client:
    """One connection's outbound queue of ``(seq, json_text)``.

    ``batch``: the client takes several messages per frame (``/ws?batch=1``).
    """

    queue: asyncio.Queue[tuple[int, str]]
    batch: bool = False
    last_sent: int = 0
    overflowed: bool = False
    send_lock: asyncio.Lock = field(default_factory=asyncio.Lock)


class Hub:
    """The set of connected clients.

    Parameters
    ----------
    queue_size : int
        Messages buffered per client.
    batch_max_messages, batch_max_chars : int
        A ``batch`` frame's cap: messages, and characters of their texts (a single
        longer message still goes, alone).
    """

    def __init__(
        self,
        queue_size: int,
        batch_max_messages: int = BATCH_MAX_MESSAGES,
        batch_max_chars: int = BATCH_MAX_CHARS,
    ) -> None:
        self.queue_size = queue_size
        self.batch_max_messages = min(batch_max_messages, BATCH_MAX_MESSAGES)
        self.batch_max_chars = batch_max_chars
        self.clients: set[Client] = set()
        self.last_seq = 0
        self.n_dropped = 0
        self._loop: asyncio.AbstractEventLoop | None = None

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        """Remember the event loop that owns the clients."""
        self._loop = loop

    def register(self, *, batch: bool = False) -> Client:
        """A new client (call on the event loop); ``batch``: it opted in to batch frames."""
        client = Client(asyncio.Queue(self.queue_size), batch=batch)
        self.clients.add(client)
        return client

    def unregister(self, client: Client) -> None:
        """Forget ``client``."""
        self.clients.discard(client)

    def publish(self, messages: list[dict[str, Any]]) -> None:
        """Queue messages (dicts with ``seq``) for every client; on the event loop."""
        items = [(int(m["seq"]), encoded(m)) for m in messages]
        if items:
            self.last_seq = max(self.last_seq, items[-1][0])
        for client in list(self.clients):
            if client.overflowed:
                continue
            for item in items:
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


def batch_text(texts: list[str]) -> str:
    """One ``batch`` message holding the encoded messages ``texts``, joined as text."""
    return _BATCH_HEAD + ",".join(texts) + "]}"


def take(
    client: Client, first: tuple[int, str], max_messages: int, max_chars: int
) -> tuple[list[tuple[int, str]], bool]:
    """``first`` and what else ``client``'s queue holds now, up to a frame's cap.

    Never waits (call on the event loop). Returns the items in queue order and whether
    :data:`OVERFLOW` was met (it ends the list and is not part of it).
    """
    items = [first]
    chars = len(first[1])
    while len(items) < max_messages and chars < max_chars and not client.queue.empty():
        item = client.queue.get_nowait()
        if item == OVERFLOW:
            return items, True
        items.append(item)
        chars += len(item[1])
    return items, False


def pack(texts: list[str], max_messages: int, max_chars: int) -> list[str]:
    """Frames for ``texts`` in order: a lone message as is, several as one ``batch``.

    A frame holds at most ``max_messages`` messages and stops growing once they hold
    ``max_chars`` characters.
    """
    groups: list[list[str]] = [[]]
    chars = 0
    for text in texts:
        if len(groups[-1]) >= max_messages or chars >= max_chars:
            groups.append([])
            chars = 0
        groups[-1].append(text)
        chars += len(text)
    return [g[0] if len(g) == 1 else batch_text(g) for g in groups if g]
