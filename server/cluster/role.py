"""A server process's role in a cluster: the site's tracker while it holds the lease.

Every process on one PostgreSQL database stores and acknowledges the batches posted to
it and serves consoles. The one that holds the site lease (:mod:`.lease`) also tracks:
its :class:`~demtrack.server.ingest.pipeline.Pipeline` processes the batches it received
itself and, in detection-id order, those the other processes stored
(:meth:`~demtrack.server.ingest.pipeline.Pipeline.catch_up`): before each of its own
batches (so its own never overtake earlier ones), and every :data:`POLL_S` by a poller
thread (the other processes' batches are found by polling the detections after the
newest id it has taken, an indexed read that returns nothing when idle; the database
gives ids in commit order, so none is ever skipped). Tracking every batch in id order
makes the tracks those of one process that received the batches in that order.

A keeper thread renews the lease every third of ``ttl_s``. A process that fails to
renew, or whose write the fence refused, stops tracking at once; the others try to
acquire the lease every third of ``ttl_s`` and the first to get it (once the old one has
expired: at most ``ttl_s`` after the last renewal) starts tracking from the durable state,
with the start-up replay (:meth:`~demtrack.server.ingest.pipeline.Pipeline.lead`).
"""

from __future__ import annotations

import logging
import os
import secrets
import socket
import threading
import time
from typing import Any

from ..ingest.pipeline import Pipeline
from ..store.integrity import StoreUnavailableError
from .lease import SiteLease

__all__ = ["POLL_S", "ClusterRole", "process_owner"]

log = logging.getLogger("demtrack.server")

#: How often (s) the tracking process looks for batches other processes stored.
POLL_S = 0.1


def process_owner() -> str:
    """A lease owner name unique to this process: host, pid and a random tag."""
    return f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"


class ClusterRole:
    """Leader or follower of ``site_id``: holds, renews and loses the lease.

    Parameters
    ----------
    lease : SiteLease
    pipeline : Pipeline
        This process's pipeline (it tracks only while the lease is held).
    site_id : str
    ttl_s : float
        The lease's time to live (s); renewals and takeover attempts every third of it.
    owner : str, optional
        This process's lease owner name (:func:`process_owner` by default).
    """

    def __init__(
        self,
        lease: SiteLease,
        pipeline: Pipeline,
        site_id: str,
        ttl_s: float,
        owner: str | None = None,
    ) -> None:
        self.lease = lease
        self.pipeline = pipeline
        self.site_id = site_id
        self.ttl_s = float(ttl_s)
        self.owner = owner or process_owner()
        #: The lease token this process tracks with; None while it follows.
        self.token: int | None = None
        #: Times this process started tracking (the first start included).
        self.n_led = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._last_renewed = time.monotonic()

    @property
    def leading(self) -> bool:
        """Whether this process tracks the site now."""
        return self.token is not None and self.pipeline.tracking

    # ------------------------------------------------------------------ life
    def start(self) -> dict[str, int]:
        """Follow, try the lease once (tracking at once if it is free), start the threads.

        The keeper runs before the start-up replay, so the lease is renewed while it
        replays. Returns the replay's counts (zeros when another process tracks).
        """
        self.pipeline.follow()
        token = self.lease.acquire(self.site_id, self.owner, self.ttl_s)
        with self._lock:
            self.token = token
        for name, target in (("lease", self._keep), ("catch-up", self._poll)):
            t = threading.Thread(target=target, name=f"demtrack-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        counts = self._lead(token) if token is not None else None
        return counts or {"replayed": 0, "processed": 0}

    def stop(self) -> None:
        """Stop tracking and the threads, and hand the lease over now (clean shutdown)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=self.ttl_s + 5.0)
        with self.pipeline._lock:  # noqa: SLF001 - no batch is being tracked meanwhile
            self.pipeline.tracking = False
            token, self.token = self.token, None
        if token is not None:
            try:
                self.lease.release(self.site_id, self.owner, token)
            except Exception:  # noqa: BLE001 - it expires by itself
                log.warning("could not release the site lease; it expires in %g s", self.ttl_s)

    # ------------------------------------------------------------------ lead / lose
    def _lead(self, token: int) -> dict[str, int] | None:
        """Track with ``token``: the start-up replay, then live. None if it was lost."""
        fence = SiteLease.fence_check(self.site_id, token, on_stale=lambda: self._lose(token))
        log.info("site %s: this process tracks it now (lease token %d)", self.site_id, token)
        try:
            counts = self.pipeline.lead(fence)
        except StoreUnavailableError as exc:  # fenced out (or no store) while replaying
            log.error("taking over the tracking stopped: %s", exc)
            self._lose(token)
            return None
        except Exception:  # noqa: BLE001 - never hold a lease one does not track with
            log.exception("taking over the tracking failed; handing the lease back")
            self._lose(token)
            try:
                self.lease.release(self.site_id, self.owner, token)
            except Exception:  # noqa: BLE001 - it expires by itself
                log.warning("could not release the site lease; it expires in %g s", self.ttl_s)
            return None
        with self._lock:
            if self.token != token:  # lost while replaying
                self.pipeline.tracking = False
                return None
            self.n_led += 1
        log.info("replayed %(replayed)d fixes, processed %(processed)d detections", counts)
        return counts

    def _lose(self, token: int) -> None:
        """Stop tracking now (a failed renewal or a fenced write of ``token``)."""
        with self._lock:
            if self.token != token:
                return
            self.token = None
            self.pipeline.tracking = False  # read under the pipeline's lock by every batch
        log.warning("site %s: lease lost; this process stops tracking", self.site_id)

    # ------------------------------------------------------------------ threads
    def _keep(self) -> None:
        """Renew the lease while held; try to take it over while not."""
        period = self.ttl_s / 3.0
        while not self._stop.wait(period):
            token = self.token
            try:
                if token is None:
                    new = self.lease.acquire(self.site_id, self.owner, self.ttl_s)
                    if new is not None and not self._stop.is_set():
                        with self._lock:  # renewed by this loop while the replay runs
                            self.token = new
                            self._last_renewed = time.monotonic()
                        threading.Thread(
                            target=self._lead, args=(new,), name="demtrack-take-over", daemon=True
                        ).start()
                elif self.lease.renew(self.site_id, self.owner, token, self.ttl_s):
                    self._last_renewed = time.monotonic()
                else:
                    self._lose(token)
            except Exception as exc:  # noqa: BLE001 - the database is unreachable: retry
                log.warning("site lease: %s", exc)
                if token is not None and time.monotonic() - self._last_renewed > self.ttl_s:
                    self._lose(token)

    def _poll(self) -> None:
        """Take up the batches other processes stored, while tracking."""
        pipeline = self.pipeline
        while not self._stop.wait(POLL_S):
            after = pipeline.tail_after
            if not self.leading or after is None:
                continue
            try:
                if pipeline.store.detections(after, 1, unprocessed=True):
                    pipeline.catch_up()
            except StoreUnavailableError as exc:  # fenced out: _lose has run
                log.error("tracking stopped: %s", exc)
            except Exception:  # noqa: BLE001 - a thread: log, keep polling
                log.exception("tracking other processes' batches failed")

    def status(self) -> dict[str, Any]:
        """The role, for logs and health: owner, token, whether it tracks now."""
        return {"owner": self.owner, "token": self.token, "leading": self.leading}
