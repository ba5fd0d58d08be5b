"""The reorder buffer: fixes wait until the newest is ``lag_s`` ahead, then go in order.

Fixes wait in a heap of keys ``(t_s, sensor, detection_id)`` until the newest accepted
fix is ``lag_s`` ahead of them (scenario time), then go to the tracker in key order, so
batches from several cameras that arrive slightly out of order are tracked in time
order, and in the same order whatever the arrival order. A fix that sorts before the
last one handed over is refused (the pipeline stores it with ``tracked: false``).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator

from demtrack.core.tracking.types import Fix

__all__ = ["FixKey", "ReorderBuffer"]

#: ``(t_s, sensor, detection_id)``: the tracker's input order.
FixKey = tuple[float, str, int]


class ReorderBuffer:
    """Keys waiting for the tracker and their fixes (see the module docstring).

    Parameters
    ----------
    lag_s : float
        How far behind the newest fix a fix waits (s).

    Attributes
    ----------
    fixes : dict of int to Fix
        The tracker's fix of each waiting detection id (and of fixes just built, until
        :meth:`admit` takes or :meth:`refuse` drops them).
    newest_t : float
        The newest accepted fix time (s; -inf before any).
    released_key : FixKey
        The last key handed over.
    """

    def __init__(self, lag_s: float) -> None:
        self.lag_s = float(lag_s)
        self.heap: list[FixKey] = []
        self.fixes: dict[int, Fix] = {}
        self.newest_t = -math.inf
        self.released_key: FixKey = (-math.inf, "", -1)

    def __len__(self) -> int:
        return len(self.heap)

    def load(self, keys: list[FixKey]) -> None:
        """Start from ``keys``, sorted (a sorted list is a heap): the start-up replay."""
        self.heap = keys
        if keys:
            self.newest_t = max(k[0] for k in keys)

    def admit(self, key: FixKey) -> bool:
        """Queue ``key``; False (and its fix dropped) when it sorts before what was handed over."""
        if key < self.released_key:
            self.fixes.pop(key[2], None)
            return False
        heapq.heappush(self.heap, key)
        self.newest_t = max(self.newest_t, key[0])
        return True

    def due(self) -> Iterator[tuple[FixKey, Fix | None]]:
        """Pop the keys at most ``lag_s`` behind the newest (as of the call), in order.

        Each comes with its fix (None if none was stored for it); the key is the new
        :attr:`released_key` when it is yielded.
        """
        horizon = self.newest_t - self.lag_s
        heap, fixes = self.heap, self.fixes
        while heap and heap[0][0] <= horizon:
            key = heapq.heappop(heap)
            self.released_key = key
            yield key, fixes.pop(key[2], None)
