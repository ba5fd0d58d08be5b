"""The event log, followed across processes: every stored message to this process's hub.

On PostgreSQL each server process publishes the stream from the event log, whoever wrote
it (the tracker's process, another process's marker): a thread LISTENs on
:data:`CHANNEL`, which every transaction that appends events notifies with its newest
``seq``, and on each notification (or every ``poll_s`` when none comes) reads the events
after the last one it published (``store.events_since``) and hands them on in sequence
order. So a console on any process sees every message once, in order; the tracker's own
process publishes nothing itself (its pipeline's publisher is a no-op on PostgreSQL).

The store numbers events under an advisory lock held to the commit, so numbers become
visible in order; should a hole appear all the same (events deleted by hand, a future
numbering), the messages after it are held back until it fills or ``gap_wait_s`` has
passed, and the hole is logged.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ..store.postgres.dialect import EVENT_CHANNEL as CHANNEL

__all__ = ["CHANNEL", "EventTail"]

log = logging.getLogger("demtrack.server")

_PAGE = 1000


class EventTail:
    """Publishes the store's events after ``after`` as they commit (a daemon thread).

    Parameters
    ----------
    url : str
        The database's ``postgresql://`` URL (the thread LISTENs on its own connection).
    events_since : callable
        ``events_since(seq, limit)`` -> stored messages with ``seq`` filled in, oldest
        first (:meth:`Store.events_since`).
    publish : callable
        Receives each run of messages, in sequence order.
    after : int
        The newest ``seq`` already published (or not to be: the stream's start).
    poll_s : float
        Longest wait for a notification before the log is read anyway (s).
    gap_wait_s : float
        How long messages after a hole in the sequence wait for it (s).
    """

    def __init__(
        self,
        url: str,
        events_since: Callable[[int, int], list[dict[str, Any]]],
        publish: Callable[[list[dict[str, Any]]], None],
        after: int,
        *,
        poll_s: float = 1.0,
        gap_wait_s: float = 2.0,
    ) -> None:
        self.url = url
        self.events_since = events_since
        self.publish = publish
        self.after = int(after)
        self.poll_s = float(poll_s)
        self.gap_wait_s = float(gap_wait_s)
        #: Sequence numbers given up on (never appeared within ``gap_wait_s``).
        self.n_skipped = 0
        self._gap_since: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> EventTail:
        """LISTEN (before the first read: nothing is missed between) and start the thread."""
        import psycopg

        conn = psycopg.connect(self.url, autocommit=True)
        conn.execute(f"LISTEN {CHANNEL}")
        self._thread = threading.Thread(
            target=self._run, args=(conn,), name="demtrack-event-tail", daemon=True
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread (within ``poll_s``) and close its connection."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.poll_s + 5.0)

    def _run(self, conn: Any) -> None:
        try:
            while not self._stop.is_set():
                try:
                    self.drain()
                except Exception:  # noqa: BLE001 - a thread: log, keep following
                    log.exception("reading the event log failed")
                wait = self.poll_s if self._gap_since is None else min(self.poll_s, 0.05)
                for _ in conn.notifies(timeout=wait, stop_after=1):
                    pass
        except Exception:  # noqa: BLE001 - the connection failed: say so once
            if not self._stop.is_set():
                log.exception("event log listener stopped")
        finally:
            conn.close()

    def drain(self) -> int:
        """Publish every message now readable after :attr:`after`; how many.

        Stops at a hole younger than ``gap_wait_s`` (the next call looks again).
        """
        n = 0
        while True:
            rows = self.events_since(self.after, _PAGE)
            run: list[dict[str, Any]] = []
            for m in rows:
                seq = int(m["seq"])
                if seq != self.after + 1 and not self._gap_expired():
                    break
                if seq != self.after + 1:
                    self.n_skipped += seq - self.after - 1
                    log.warning("event log: seq %d to %d never appeared", self.after + 1, seq - 1)
                self._gap_since = None
                run.append(m)
                self.after = seq
            if run:
                self.publish(run)
                n += len(run)
            if len(run) < len(rows) or len(rows) < _PAGE:
                return n

    def _gap_expired(self) -> bool:
        """Whether the hole after :attr:`after` was first seen ``gap_wait_s`` ago."""
        now = time.monotonic()
        if self._gap_since is None:
            self._gap_since = now
        return now - self._gap_since >= self.gap_wait_s
