"""Which stored points of a track changed between two of its versions (``track_rev``).

A live track is rewritten many times a second, but each write replaces only its points
from one index on (``points_from``: new points and the smoother's revised tail).
:class:`PointCuts` remembers, for the recent writes of each track made through one
:class:`~demtrack.server.store.database.Store`, the version before, the version after and
that index.
A reader holding version ``R`` of a track whose stored version is now ``N`` then needs only
the points from the smallest index written along the chain of writes ``R -> ... -> N``;
the ones before it are those it holds. When the chain is not complete (writes by another
connection or process, a version older than the kept history, a replace of the whole
table) the answer is "unknown" and the reader reads the whole body.

Writes are recorded inside their transaction, before it commits: a reader can never see a
committed version whose write is not recorded. A write that rolls back leaves an entry
whose version no committed row has (or that a later write reuses, AUTOINCREMENT being
rolled back too); following such an entry can only lower the index found, so answers stay
exact, at worst reading a few more points than needed.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque
from collections.abc import Mapping

__all__ = ["PointCuts"]

#: Writes remembered per track (a reader further behind reads the whole body). A live
#: track is written with every ingest commit: at 10x replay speed, 60 or more times between
#: two polls of the console's synopsis (every 3 s), which 32 did not cover.
WRITES_PER_TRACK = 256
#: Tracks remembered (least recently written forgotten first): at most about 16 MB.
MAX_TRACKS = 1024


class PointCuts:
    """Recent writes of each track: ``(rev before, rev after, first point rewritten)``.

    Thread-safe.
    """

    def __init__(
        self, writes_per_track: int = WRITES_PER_TRACK, max_tracks: int = MAX_TRACKS
    ) -> None:
        self._writes = writes_per_track
        self._max_tracks = max_tracks
        self._lock = threading.Lock()
        self._by_track: OrderedDict[int, deque[tuple[int, int, int]]] = OrderedDict()

    def record(
        self, before: Mapping[int, int], after: Mapping[int, int], starts: Mapping[int, int]
    ) -> None:
        """One write of tracks ``starts`` (id -> first point rewritten).

        ``before`` and ``after``: their versions before and after it (an id missing from
        ``before`` had no version: a new track, or one from a file older than versions).
        """
        with self._lock:
            for track_id, start in starts.items():
                new = after.get(track_id)
                if new is None:
                    continue
                log = self._by_track.pop(track_id, None)
                if log is None:
                    log = deque(maxlen=self._writes)
                log.append((before.get(track_id, -1), new, int(start)))
                self._by_track[track_id] = log  # most recently written last
            while len(self._by_track) > self._max_tracks:
                self._by_track.popitem(last=False)

    def clear(self) -> None:
        """Forget every write (after the tracks table was replaced)."""
        with self._lock:
            self._by_track.clear()

    def first_changed(self, track_id: int, held: int, now: int) -> int | None:
        """Smallest point index rewritten from version ``held`` to ``now``; None if unknown."""
        if held == now:
            return None
        with self._lock:
            log = self._by_track.get(track_id)
            entries = list(log) if log is not None else []
        # Follow the chain held -> ... -> now; several entries may start from one version
        # (a rolled-back write's number reused): take every one, keep the smallest index.
        steps: dict[int, list[tuple[int, int]]] = {}
        for old, new, start in entries:
            if new <= now:
                steps.setdefault(old, []).append((new, start))
        first: int | None = None
        rev = held
        while rev != now:
            step = steps.get(rev)
            if not step:
                return None
            rev = max(new for new, _ in step)
            lowest = min(start for _, start in step)
            first = lowest if first is None else min(first, lowest)
        return first
