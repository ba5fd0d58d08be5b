"""A derived write fenced out of a lost cluster lease is dropped, never held for retries.

A full disk's refusal passes once space returns, so that write is held and retried
(``test_pipeline_disk_full.py``); a fenced write carries the old lease token and can
never pass: held, it would be retried on the timer for as long as the process ran.
"""

from __future__ import annotations

import threading
from typing import Any

from demtrack.server.cluster.lease import FencedOut
from demtrack.server.ingest.held_writes import HeldWrites
from demtrack.server.store.database import Store
from demtrack.server.store.integrity import StoreFullError


def _refusing(store: Store, *errors: Exception) -> list[int]:
    """Make the store's next derived writes raise ``errors`` in turn; counts real writes."""
    real = store.write_derived
    queue = list(errors)
    stored = [0]

    def write(*a: Any, **kw: Any) -> Any:
        if queue:
            raise queue.pop(0)
        stored[0] += 1
        return real(*a, **kw)

    store.write_derived = write  # type: ignore[method-assign]
    return stored


def _writes(store: Store) -> HeldWrites:
    w = HeldWrites(store, lambda _messages: None, threading.Lock())
    w._delay = w.max_retry_s = 3600.0  # no timer: only the calls below retry
    return w


def test_a_fenced_write_is_dropped_not_held(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    try:
        stored = _refusing(store, FencedOut("lease lost"))
        w = _writes(store)
        assert w.write([], [], [], []) is False
        assert not w.held and w.n_dropped == 1 and w._timer is None
        assert w.write([], [], [], []) is True  # the next write is not behind it
        assert stored[0] == 1
    finally:
        store.close()


def test_writes_held_behind_a_full_disk_are_dropped_when_the_retry_is_fenced(tmp_path):
    store = Store(tmp_path / "s.sqlite3")
    try:
        stored = _refusing(store, StoreFullError("disk full"), FencedOut("lease lost"))
        w = _writes(store)
        assert w.write([], [], [], []) is False  # disk full: held
        assert len(w.held) == 1 and w.n_dropped == 0
        assert w.write([], [], [], []) is False  # the held one is fenced: both dropped
        assert not w.held and w.n_dropped == 2
        assert w.flush() is True and stored[0] == 0
    finally:
        store.close()
