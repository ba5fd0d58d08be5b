"""The CoT sender: a stream subscriber that never slows ingest.

:meth:`CotSender.publish` is handed every batch of published messages, as the WebSocket
hub and the 3D scene are (``app._fan_out``), from the pipeline's thread under its lock;
it only puts the batch in a bounded queue (``put_nowait``) and, when that is full, drops
it and counts it (``n_dropped``). A worker thread turns the queued messages into events
and sends them; of several updates of one track (or marker) waiting together only the
newest is sent, so a slow network loses intermediate positions, not the latest one.
On start the stored markers are sent once, so a TAK peer sees them without waiting for a
change.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Iterable
from typing import Any

from demtrack.core.io.cot import CotEvent, event_to_xml

from .events import CotBuilder
from .transport import Transport

__all__ = ["CotSender"]

log = logging.getLogger("demtrack.server.cot")
_STOP: list[dict[str, Any]] = []


class CotSender:
    """Follows the published stream and sends CoT events.

    Parameters
    ----------
    builder : CotBuilder
        Turns messages into events.
    transport : Transport
        UDP or TCP.
    queue_size : int
        Batches of messages buffered before new ones are dropped.
    """

    def __init__(self, builder: CotBuilder, transport: Transport, queue_size: int = 1000) -> None:
        self.builder = builder
        self.transport = transport
        self.queue: queue.Queue[list[dict[str, Any]]] = queue.Queue(queue_size)
        self.n_dropped = 0  # batches of messages dropped on a full queue
        self.n_sent = 0  # events that left
        self.n_failed = 0  # events the transport dropped (peer down, network error)
        self._thread: threading.Thread | None = None

    def publish(self, messages: list[dict[str, Any]]) -> None:
        """Queue a batch of published messages; drop it if the queue is full. Never waits."""
        if not messages:
            return
        try:
            self.queue.put_nowait(list(messages))
        except queue.Full:
            self.n_dropped += 1

    def start(self, initial: Iterable[dict[str, Any]] = ()) -> CotSender:
        """Start the worker; ``initial`` messages (the stored markers) are sent first."""
        first = list(initial)
        self._thread = threading.Thread(
            target=self._run, args=(first,), name="demtrack-cot", daemon=True
        )
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the worker after what is queued and close the transport."""
        if self._thread is not None:
            try:
                self.queue.put(_STOP, timeout=timeout_s)
            except queue.Full:
                pass
            self._thread.join(timeout_s)
            self._thread = None
        self.transport.close()

    def _events(self, batches: list[list[dict[str, Any]]]) -> list[CotEvent]:
        newest: dict[str, CotEvent] = {}
        for batch in batches:
            for message in batch:
                try:
                    for ev in self.builder.events(message):
                        newest.pop(ev.uid, None)  # re-insert: keep send order by newest
                        newest[ev.uid] = ev
                except Exception:  # noqa: BLE001 - one bad message must not stop the feed
                    log.exception("CoT: cannot make an event of a %s message", message.get("type"))
        return list(newest.values())

    def _send(self, events: list[CotEvent]) -> None:
        for ev in events:
            if self.transport.send(event_to_xml(ev)):
                self.n_sent += 1
            else:
                self.n_failed += 1

    def _run(self, initial: list[dict[str, Any]]) -> None:
        if initial:
            self._send(self._events([initial]))
        while True:
            batches = [self.queue.get()]
            while True:  # everything waiting now, so stale updates can be skipped
                try:
                    batches.append(self.queue.get_nowait())
                except queue.Empty:
                    break
            stop = any(b is _STOP for b in batches)
            self._send(self._events([b for b in batches if b is not _STOP]))
            if stop:
                return
