"""The online tracker, fed from the reorder buffer, and the bound on its memory.

The tracker forgets tracks that ended more than ``keep_ended_s`` ago (scenario time),
after their final form is stored: memory stays bounded over a long run while SQLite
and the API keep every track. The start-up replay forgets them as it goes (every
:data:`REPLAY_DROP_EVERY` fixes) and leaves their stored rows alone.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from demtrack.core.errors import DemtrackError
from demtrack.core.tracking.tracker import Tracker

from .reorder import ReorderBuffer

__all__ = ["REPLAY_DROP_EVERY", "TrackerFeed"]

log = logging.getLogger("demtrack.server")

#: The start-up replay forgets old ended tracks every this many fixes.
REPLAY_DROP_EVERY = 4096


class TrackerFeed:
    """Hands due fixes to ``tracker`` in order; ``released_t``: the newest handed over (s)."""

    def __init__(self, tracker: Tracker, buffer: ReorderBuffer) -> None:
        self.tracker = tracker
        self.buffer = buffer
        self.released_t = -math.inf

    def release(self, drop: Callable[[], list[int]] | None = None) -> int:
        """Hand the due fixes to the tracker; the number handed over.

        ``drop``: called every :data:`REPLAY_DROP_EVERY` fixes and at the end (the
        start-up replay, whose tracks are already stored, forgets old ended tracks).
        """
        n = 0
        update = self.tracker.update
        released = self.released_t
        for (t, _, det_id), fix in self.buffer.due():
            if drop is not None and n % REPLAY_DROP_EVERY == REPLAY_DROP_EVERY - 1:
                self.released_t = released
                drop()
            if fix is None:
                log.error("no valid fix for stored detection %s", det_id)
            else:
                try:
                    update(fix, index=det_id)
                except DemtrackError:  # cannot happen in time order; never stop the stream
                    log.exception("tracker refused fix %s", det_id)
            released = max(released, t)
            n += 1
        self.released_t = released
        if drop is not None:
            drop()
        return n

    def drop_ended(self, keep_ended_s: float) -> list[int]:
        """Forget tracks that ended more than ``keep_ended_s`` before :attr:`released_t`."""
        if not math.isfinite(self.released_t):
            return []
        return list(self.tracker.drop_ended(self.released_t - keep_ended_s))
