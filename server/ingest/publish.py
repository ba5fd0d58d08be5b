"""Derived rows stored, then published as the text the store wrote.

A batch's stream messages are encoded once, when the store writes them to the event
log (:meth:`~demtrack.server.store.database.Store.write_derived`); the hub is handed that
text with its ``seq`` appended (:func:`~demtrack.server.store.codec.published_text`),
never an encoding of its own.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from ..hub import StreamMessage
from ..store.backend import StoreBackend
from ..store.codec import payload_dict, published_text
from ..store.derived import FixRow
from .stream_messages import SensorStatusPayload, StreamPayload

__all__ = ["Publisher", "sensor_status_messages", "store_and_publish"]

#: ``publish(messages)``: each message a dict with ``seq`` (called under the lock, in order).
Publisher = Callable[[list[dict[str, Any]]], None]


def sensor_status_messages(
    sensors: Sequence[str], last_t: Mapping[str, float], n_det: Mapping[str, int]
) -> list[tuple[str, StreamPayload]]:
    """The ``sensor_status`` message of each of ``sensors`` (in the order given)."""
    return [
        ("sensor_status", SensorStatusPayload(s, last_t.get(s), n_det.get(s, 0))) for s in sensors
    ]


def store_and_publish(
    store: StoreBackend,
    publish: Publisher,
    fixes: Sequence[FixRow],
    tracks: Sequence[dict[str, Any]],
    events: Sequence[tuple[str, StreamPayload]],
    activity: Sequence[dict[str, Any]],
    stored_hook: Callable[[Sequence[dict[str, Any]]], None] | None = None,
    *,
    fence: Callable[[Any], None] | None = None,
) -> None:
    """Write a batch's derived rows in one transaction, then publish its messages in order.

    ``stored_hook(tracks)``: called once the rows are written, before publishing (the
    track bodies' points are then clean). ``fence``: the cluster lease's check, run in
    the write's transaction (:meth:`demtrack.server.cluster.lease.SiteLease.fence_check`);
    a write that it refuses raises and publishes nothing.
    """
    stored = store.write_derived(fixes, tracks, events, activity=activity, fence=fence)
    if stored_hook is not None:
        stored_hook(tracks)
    publish(
        [
            StreamMessage(payload_dict(p), s, published_text(text, s))
            for (_, p), (s, text) in zip(events, stored, strict=True)
        ]
    )
