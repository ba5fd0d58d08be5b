"""Derived writes of acknowledged batches that a full store refused, retried until they pass.

A batch is acknowledged once its detections commit; its derived rows (fixes, tracks,
activity, stream events) are written after it is processed, in a transaction of their own.
A disk that fills between the two refused that second write and the rows were only made
at the next restart (which processes stored but unprocessed detections). Now each derived
write goes through :class:`HeldWrites`: a write the store cannot make now
(:class:`~demtrack.server.store.integrity.StoreUnavailableError`: nothing of it was
written) is held, in order, and tried again, with every later one behind it, at the next
write and on a timer (``retry_s``, doubling up to ``max_retry_s``) until space returns. The
rows and messages are the ones computed when the batch was processed, so the store ends
as an uninterrupted run leaves it; the stream's messages go out late, in their order.

A refusal that can never pass (``retryable`` False: a write fenced out of a lost cluster
lease, whose fence holds the old token) is not held: that write and every one held behind
it (made under the same lease) are dropped, since the process that holds the lease now
derives them from the durable state (the batches' detections are stored and acknowledged;
the lease's own check has already stopped this process tracking).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from ..store.backend import StoreBackend
from ..store.derived import FixRow
from ..store.integrity import StoreUnavailableError
from .publish import Publisher, store_and_publish
from .stream_messages import StreamPayload

__all__ = ["HeldWrites"]

log = logging.getLogger("demtrack.server")


@dataclass(frozen=True)
class _Write:
    fixes: Sequence[FixRow]
    tracks: Sequence[dict[str, Any]]
    events: Sequence[tuple[str, StreamPayload]]
    activity: Sequence[dict[str, Any]]
    stored_hook: Callable[[Sequence[dict[str, Any]]], None] | None
    fence: Any


class HeldWrites:
    """A pipeline's derived writes, in order; those the store refused wait and are retried.

    Parameters
    ----------
    store, publish
        As :func:`.publish.store_and_publish` takes them.
    lock
        The pipeline's lock: the retry timer takes it, as every other write holds it.
    retry_s, max_retry_s : float
        The first retry's delay after a refusal, and the most it doubles to (s).
    """

    def __init__(
        self,
        store: StoreBackend,
        publish: Publisher,
        lock: Any,
        *,
        retry_s: float = 0.5,
        max_retry_s: float = 10.0,
    ) -> None:
        self.store = store
        self.publish = publish
        self.lock = lock
        self.retry_s = float(retry_s)
        self.max_retry_s = float(max_retry_s)
        self.held: deque[_Write] = deque()
        self._delay = self.retry_s
        self._timer: threading.Timer | None = None
        self._closed = False
        #: Derived writes dropped because they could never pass (fenced out).
        self.n_dropped = 0

    def write(
        self,
        fixes: Sequence[FixRow],
        tracks: Sequence[dict[str, Any]],
        events: Sequence[tuple[str, StreamPayload]],
        activity: Sequence[dict[str, Any]],
        stored_hook: Callable[[Sequence[dict[str, Any]]], None] | None = None,
        *,
        fence: Any = None,
    ) -> bool:
        """Write one batch's derived rows after those held (lock held).

        False if they were not stored now: held for a retry, or dropped (a refusal that
        can never pass).
        """
        w = _Write(fixes, tracks, events, activity, stored_hook, fence)
        if not self.held:  # the common case: no queue, one call
            try:
                self._store(w)
                return True
            except StoreUnavailableError as exc:
                if not exc.retryable:
                    self._drop(w, exc)
                    return False
                self._hold(w, exc)
                return False
        self.held.append(w)
        return self.flush()

    def flush(self) -> bool:
        """Write the held writes in order (lock held); True when all were stored.

        False when some are still held, or were dropped (a refusal that can never pass).
        """
        n = len(self.held)
        while self.held:
            try:
                self._store(self.held[0])
            except StoreUnavailableError as exc:
                if not exc.retryable:
                    self._drop(self.held[0], exc)
                    return False
                log.debug("held derived writes still refused: %s", exc)
                self._arm()
                return False
            self.held.popleft()
        if n:
            log.warning("the store writes again: %d held derived write(s) stored", n)
            self._delay = self.retry_s
        return True

    def _store(self, w: _Write) -> None:
        store_and_publish(
            self.store,
            self.publish,
            w.fixes,
            w.tracks,
            w.events,
            w.activity,
            w.stored_hook,
            fence=w.fence,
        )

    def _drop(self, w: _Write, exc: StoreUnavailableError) -> None:
        """Forget ``w`` and every held write (none can pass: ``exc`` is not retryable)."""
        n = len(self.held) + (0 if self.held and self.held[0] is w else 1)
        log.warning("%d derived write(s) dropped, never to pass: %s", n, exc)
        self.held.clear()
        self.n_dropped += n
        self._delay = self.retry_s
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _hold(self, w: _Write, exc: StoreUnavailableError) -> None:
        self.held.append(w)
        log.error(
            "derived rows of acknowledged batches held (retried until the store writes): %s",
            exc,
        )
        self._arm()

    def _arm(self) -> None:
        if self._closed or (self._timer is not None and self._timer.is_alive()):
            return
        delay, self._delay = self._delay, min(2 * self._delay, self.max_retry_s)
        self._timer = threading.Timer(delay, self._retry)
        self._timer.daemon = True
        self._timer.start()

    def _retry(self) -> None:
        try:
            with self.lock:
                self._timer = None
                if not self._closed and self.held:
                    self.flush()
        except Exception:  # noqa: BLE001 - a timer thread: log, never raise
            log.exception("retrying held derived writes failed")

    def close(self) -> None:
        """Stop retrying (before the store closes); what is held is left to the restart."""
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
