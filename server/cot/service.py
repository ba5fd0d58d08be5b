"""Starting the CoT sender from the settings (the app's lifespan calls this)."""

from __future__ import annotations

from typing import Any

from demtrack.core.site.folder import Site

from .events import CotBuilder
from .sender import CotSender
from .target import parse_cot_url
from .transport import open_transport

__all__ = ["start_cot_sender"]


def start_cot_sender(
    url: str,
    site: Site,
    store_id: str,
    markers: list[dict[str, Any]],
    *,
    track_stale_s: float,
    marker_stale_s: float,
    queue_size: int,
) -> CotSender:
    """A started sender to ``url`` that first sends the stored ``markers``.

    Raises
    ------
    SettingsError
        For a URL :func:`~demtrack.server.cot.target.parse_cot_url` refuses.
    """
    target = parse_cot_url(url)
    builder = CotBuilder(
        store_id, site.dem, track_stale_s=track_stale_s, marker_stale_s=marker_stale_s
    )
    sender = CotSender(builder, open_transport(target), queue_size=queue_size)
    initial = [{"type": "marker", "action": "add", "id": m["id"], "marker": m} for m in markers]
    return sender.start(initial)
