"""Cyclic garbage-collector settings for the long-running server process.

Called once start-up is done (by ``demtrack serve`` and the replay benchmark): what is
alive then is frozen and the collection thresholds are raised.
"""

from __future__ import annotations

import gc

__all__ = ["SERVER_GC_THRESHOLDS", "tune_gc_for_serving"]

#: Cyclic-GC thresholds for the long-running server (CPython's default: 700, 10, 10).
SERVER_GC_THRESHOLDS = (10_000, 20, 100)


def tune_gc_for_serving() -> None:
    """Make the cyclic garbage collector cheap for a long-lived server's large heap.

    The server holds many long-lived objects (tracks, their points and JSON, the reorder
    buffer); with CPython's default thresholds the full collections that walk all of them
    came often enough that CPU per detection more than doubled after three minutes of a
    20-track replay (1.4 -> 3.6 ms in-process; 1.5 ms with the collector off). Objects
    alive once start-up is done are frozen (never scanned again) and the thresholds
    raised: young garbage is still collected, full collections are rare. Memory freed
    by reference counting (nearly all of it here) is unaffected.
    """
    gc.freeze()
    gc.set_threshold(*SERVER_GC_THRESHOLDS)
