"""One server process of a cluster: its role (tracker or not) and its stream follower.

:func:`start_node` is what the app's lifespan calls on PostgreSQL: it makes the lease
table's client, starts the :class:`~.role.ClusterRole` (tracking at once when the lease
is free) and the :class:`~.event_tail.EventTail` that feeds the process's subscribers
(the WebSocket hub, the 3D scene, CoT) from the event log.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..ingest.pipeline import Pipeline
from .event_tail import EventTail
from .lease import SiteLease
from .role import ClusterRole

__all__ = ["ClusterNode", "start_node"]


@dataclass(eq=False)
class ClusterNode:
    """A started cluster process: ``role``, ``tail`` and the start-up replay's ``counts``."""

    lease: SiteLease
    role: ClusterRole
    tail: EventTail
    counts: dict[str, int]

    def stop(self) -> None:
        """Hand the lease over, stop following the log, close the lease's connection."""
        self.role.stop()
        self.tail.stop()
        self.lease.close()


def start_node(
    url: str,
    pipeline: Pipeline,
    site_id: str,
    ttl_s: float,
    publish: Callable[[list[dict[str, Any]]], None],
) -> ClusterNode:
    """Join the cluster on the database at ``url``: follow, or track if the lease is free.

    ``publish`` receives every stream message stored after the call (the start-up
    replay's included), in sequence order, whichever process wrote it; the pipeline's
    own publisher must publish nothing (it would send the tracker's messages twice).
    """
    store = pipeline.store
    tail = EventTail(url, store.events_since, publish, store.last_seq()).start()
    lease = SiteLease(url, lock_timeout_s=ttl_s)
    role = ClusterRole(lease, pipeline, site_id, ttl_s)
    return ClusterNode(lease, role, tail, role.start())
