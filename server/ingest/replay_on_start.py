"""The start-up replay: the stored fixes rebuild the tracker the live run had.

The stored ``tracked`` fixes are read in detection order, turned into the tracker's fixes
by the same codec the live run used (:func:`~.fix_codec.fixes_from_bodies`, one call per
chunk) and sorted by ``(t_s, sensor, detection_id)``; the pipeline then hands over those
at most ``reorder_lag_s`` behind the newest and keeps the rest in the reorder buffer:
the same state as before the restart.
"""

from __future__ import annotations

import logging

from demtrack.core.errors import DemtrackError

from ..store.backend import StoreBackend
from .fix_codec import fix_from_body, fixes_from_bodies
from .reorder import FixKey, ReorderBuffer

__all__ = ["CHUNK", "load_stored_fixes"]

log = logging.getLogger("demtrack.server")

#: Stored fixes read per query.
CHUNK = 5000


def load_stored_fixes(store: StoreBackend, buffer: ReorderBuffer) -> int:
    """Fill ``buffer`` with every stored fix the tracker had taken; how many.

    A body the constructor refuses (not one the server wrote) keeps its place in the
    order but gives no fix; it is logged when its turn comes.
    """
    keys: list[FixKey] = []
    after = 0
    while True:
        bodies = store.fixes(after, CHUNK)
        if not bodies:
            break
        after = bodies[-1]["detection_id"]
        tracked = [b for b in bodies if b.get("hits") is not None and b.get("tracked")]
        try:
            fixes = fixes_from_bodies(tracked)
        except DemtrackError:  # one bad body: the others one by one
            fixes = []
            for b in tracked:
                try:
                    fixes.append(fix_from_body(b))
                except DemtrackError:
                    log.exception("stored fix %s is malformed", b.get("detection_id"))
        buffer.fixes.update((f.detection_index, f) for f in fixes)
        keys += [(b["t_s"], b["sensor"], b["detection_id"]) for b in tracked]
    keys.sort()
    buffer.load(keys)
    return len(keys)
