"""The first pass's scratch of a cast: hits kept per ray, and a pool lending large buffers.

``core.raycast.cast`` casts every ray once into a buffer with room for a few hits
(:data:`_FIRST_PASS_HITS`, more for runs of one origin) and re-walks the rare rays with
more. Large first-pass buffers are lent by :data:`_SCRATCH` instead of allocated afresh.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

import numpy as np

__all__ = [
    "_FIRST_PASS_HITS",
    "_FIRST_PASS_HITS_RUNS",
    "_SCRATCH",
    "_SCRATCH_MAX_BUFFERS",
    "_SCRATCH_MAX_BYTES",
    "_SCRATCH_MIN_BYTES",
    "_ScratchPool",
    "first_pass_scratch",
]

#: Hits kept per ray in the first pass of ``mode="all"``; rays with more are re-walked.
_FIRST_PASS_HITS = 4
#: The same when the batch has runs of one origin (camera rays): their re-walks cost more
#: than the larger buffer (2 % of the bench's camera rays have more than 4 hits, 0.2 %
#: more than 8; re-walking them was ~15 % of an all-hits cast at two threads).
_FIRST_PASS_HITS_RUNS = 8
#: First-pass scratch (the hits buffer and counts of a cast) of at least this many bytes
#: is taken from a pool (``_SCRATCH``) instead of allocated: glibc maps blocks above 32 MB
#: afresh on every call (1 M camera rays: 72 MB, 20-40 ms of page faults per all-hits
#: cast), smaller ones it reuses from its heap.
_SCRATCH_MIN_BYTES = 1 << 25
#: Most buffers and bytes the pool keeps between casts (larger buffers are freed).
_SCRATCH_MAX_BUFFERS = 2
_SCRATCH_MAX_BYTES = 256 * 1024 * 1024


class _ScratchPool:
    """A few float64 scratch buffers reused by casts (thread-safe).

    :meth:`take` lends the smallest kept buffer with room for ``size`` items (or a new
    one), :meth:`give` takes it back; at most ``max_buffers`` buffers and ``max_bytes``
    bytes are kept (the smallest go first). A lent buffer belongs to one cast at a time;
    its contents are stale, and no view of it may outlive the cast.
    """

    def __init__(
        self, max_buffers: int = _SCRATCH_MAX_BUFFERS, max_bytes: int = _SCRATCH_MAX_BYTES
    ) -> None:
        self.max_buffers = max_buffers
        self.max_bytes = max_bytes
        self._free: list[np.ndarray] = []
        self._lock = threading.Lock()

    @property
    def nbytes(self) -> int:
        """Bytes kept between casts."""
        with self._lock:
            return sum(b.nbytes for b in self._free)

    def take(self, size: int) -> np.ndarray:
        """A 1-D float64 buffer of at least ``size`` items (uninitialised)."""
        with self._lock:
            fits = [i for i, b in enumerate(self._free) if len(b) >= size]
            if fits:
                return self._free.pop(min(fits, key=lambda i: len(self._free[i])))
        return np.empty(size, np.float64)

    def give(self, buf: np.ndarray) -> None:
        """Return a buffer from :meth:`take` (kept if the bounds allow)."""
        if buf.nbytes > self.max_bytes:
            return
        with self._lock:
            self._free.append(buf)
            self._free.sort(key=len, reverse=True)
            while self._free and (
                len(self._free) > self.max_buffers
                or sum(b.nbytes for b in self._free) > self.max_bytes
            ):
                self._free.pop()

    @contextlib.contextmanager
    def lend(self, size: int) -> Iterator[np.ndarray]:
        """:meth:`take` for the ``with`` block, then :meth:`give`."""
        buf = self.take(size)
        try:
            yield buf
        finally:
            self.give(buf)


#: First-pass scratch shared by all casters (so the memory it keeps is bounded per process).
_SCRATCH = _ScratchPool()


@contextlib.contextmanager
def first_pass_scratch(n: int, cap: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The first pass's hits buffer ``(n, cap)`` and counts ``(n,)``, pooled when large.

    Neither escapes the cast: hits are copied out by the gather, counts summed.
    """
    size = n * (cap + 1)
    if size * 8 < _SCRATCH_MIN_BYTES:
        yield np.empty((n, cap), np.float64), np.empty(n, np.int64)
        return
    with _SCRATCH.lend(size) as raw:
        yield raw[: n * cap].reshape(n, cap), raw[n * cap : size].view(np.int64)
