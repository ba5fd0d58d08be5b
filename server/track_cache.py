"""Decoded track bodies kept between requests, by ``(track id, stored version)``.

``GET /api/tracks``, ``/api/tracks/export`` and ``/api/synopsis`` read every track of
their window. Ended tracks never change and live ones change only at their end, so
decoding each stored body again on every request (the synopsis is polled every few
seconds while live) spends the CPU live ingest needs. :class:`TrackCache` asks the store
for the ``(id, rev)`` of the window's tracks (``tracks.rev`` changes whenever a row is
written: new points, a smoothed tail, the end of a track, a start-up rewrite) and reads
and decodes only the bodies it does not hold at that version. Of a live track it holds an
older version of, it reads only the points that changed since (``server.track_history``):
a 15-minute window of 20 live tracks at 10 Hz is about 180,000 points, decoded again on
every poll before.

Sharing
-------
A :class:`CachedTrack` and everything in its ``body`` are shared by every request that
reads the track: callers must treat them as read-only (copy a container before changing
it). :func:`clip` builds a fresh top-level dict and ``points`` list; the point dicts and
the ``sensors`` / ``gaps`` lists inside are the cached ones.
"""

from __future__ import annotations

import threading
from bisect import bisect_left, bisect_right
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .store.backend import StoreBackend
from .store.codec import loads_json
from .store.queries import TrackTail

__all__ = ["DEFAULT_MAX_BYTES", "CachedTrack", "TrackCache", "clip"]

#: Default budget, in bytes of stored JSON text (decoded, a body takes several times more).
#: The console's default synopsis window (15 minutes) of 20 tracks at 10 Hz is about 35-50
#: MB of text: with 32 MB every poll evicted what the next one read (the 10x soak spent
#: 12-13 % of the server's CPU on the synopsis, 6 % with room for the window).
DEFAULT_MAX_BYTES = 64 * 2**20

#: Derived values (e.g. synopsis trajectories) kept per cached track version.
_MEMO_SIZE = 8
_MEMO_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class CachedTrack:
    """One decoded stored track body at one version (read-only: see the module docstring).

    Attributes
    ----------
    id, rev : int
        Track id and the stored row's version (``tracks.rev``).
    body : dict
        The stored body, as :meth:`Store.tracks` returns it.
    t_s : list of float
        The points' times (s).
    in_order : bool
        The times never decrease (the tracker's points are in time order), so a time
        window is a contiguous index range found by bisection.
    nbytes : int
        Length of the stored JSON text (what the cache's budget counts).
    memo : dict
        Values derived from this version by callers (keyed by the caller; at most a
        few are kept).
    """

    id: int
    rev: int
    body: dict[str, Any]
    t_s: list[float]
    in_order: bool
    nbytes: int
    memo: dict[Any, Any] = field(default_factory=dict)

    @classmethod
    def decode(cls, track_id: int, rev: int, text: str) -> CachedTrack:
        """Decode a stored body."""
        body = loads_json(text)
        t_s = [p["t_s"] for p in body["points"]]
        in_order = all(a <= b for a, b in zip(t_s, t_s[1:], strict=False))
        return cls(track_id, rev, body, t_s, in_order, len(text))

    def extended(self, rev: int, tail: TrackTail) -> CachedTrack:
        """Version ``rev`` of this track: these points up to ``tail.first``, then the tail's.

        The body equals a decode of the whole stored text (``points`` is its last key);
        the unchanged points are shared with this version. ``nbytes`` counts the kept
        points at this version's average length per point.
        """
        k0 = tail.first
        new = loads_json("[" + ",".join(tail.points) + "]")
        body = loads_json(tail.head)
        body["points"] = self.body["points"][:k0] + new
        t_new = [p["t_s"] for p in new]
        t_s = self.t_s[:k0] + t_new
        joined = t_s[k0 - 1 : k0 + 1] if k0 > 0 else []
        in_order = (
            (self.in_order or all(a <= b for a, b in zip(t_s[:k0], t_s[1:k0], strict=False)))
            and all(a <= b for a, b in zip(joined, joined[1:], strict=False))
            and all(a <= b for a, b in zip(t_new, t_new[1:], strict=False))
        )
        n_old = max(len(self.t_s), 1)
        kept = self.nbytes * min(k0, n_old) // n_old
        nbytes = len(tail.head) + kept + sum(len(p) + 1 for p in tail.points) + 10
        return CachedTrack(self.id, rev, body, t_s, in_order, nbytes)

    def span(self, t_from: float | None, t_to: float | None) -> tuple[int, int] | None:
        """Index range ``[i0, i1)`` of the points with ``t_from <= t_s <= t_to``.

        None when the points are not in time order (the window is then no range).
        """
        if not self.in_order:
            return None
        i0 = 0 if t_from is None else bisect_left(self.t_s, t_from)
        i1 = len(self.t_s) if t_to is None else bisect_right(self.t_s, t_to)
        return i0, max(i0, i1)

    def memoized(self, key: Any, make: Callable[[], Any]) -> Any:
        """``make()`` once per ``key`` for this version (the newest few keys are kept)."""
        with _MEMO_LOCK:
            hit = self.memo.pop(key, None)
            if hit is not None:
                self.memo[key] = hit  # most recently used last
                return hit
        value = make()  # outside the lock: two threads may both make it (same value)
        with _MEMO_LOCK:
            self.memo[key] = value
            while len(self.memo) > _MEMO_SIZE:
                del self.memo[next(iter(self.memo))]
        return value


def clip(track: CachedTrack, t_from: float | None, t_to: float | None) -> dict[str, Any]:
    """The body with its points clipped to ``[t_from, t_to]``, ``first_index`` set.

    A fresh top-level dict and ``points`` list; the point dicts are shared (read-only).
    """
    body = track.body
    rng = track.span(t_from, t_to)
    if rng is not None:
        i0, i1 = rng
        return dict(body, points=body["points"][i0:i1], first_index=i0 if i1 > i0 else 0)
    pts = [
        p
        for p in body["points"]
        if (t_from is None or p["t_s"] >= t_from) and (t_to is None or p["t_s"] <= t_to)
    ]
    first = body["points"].index(pts[0]) if pts else 0
    return dict(body, points=pts, first_index=first)


class TrackCache:
    """Decoded track bodies of a :class:`Store`, least recently used evicted first.

    Parameters
    ----------
    store : StoreBackend
        Where the bodies live.
    max_bytes : int
        Budget in bytes of stored JSON text. A window larger than the budget is still
        answered in full; only what fits is kept for the next request.

    Notes
    -----
    Thread-safe: the index is guarded by a lock; bodies are decoded outside it.
    """

    def __init__(self, store: StoreBackend, max_bytes: int = DEFAULT_MAX_BYTES) -> None:
        if max_bytes < 0:
            raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
        self.store = store
        self.max_bytes = int(max_bytes)
        self.nbytes = 0
        self.hits = 0
        self.misses = 0
        self.tails = 0  # of the misses, versions built from a held one and the changed points
        self._lock = threading.Lock()
        self._tracks: OrderedDict[int, CachedTrack] = OrderedDict()

    def __len__(self) -> int:
        return len(self._tracks)

    def select(
        self,
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        cls: str | None = None,
        bbox: tuple[float, float, float, float] | None = None,
    ) -> list[CachedTrack]:
        """The tracks :meth:`Store.tracks` selects (same filters, same order), cached."""
        with self._lock:
            held = dict(self._tracks)  # what this call may reuse, whatever others evict
        known = {i: t.rev for i, t in held.items()}
        rows = self.store.track_rows(
            known, t_from=t_from, t_to=t_to, cls=cls, bbox=bbox, tails=True
        )
        out: list[CachedTrack] = []
        fresh: list[CachedTrack] = []
        n_tails = 0
        for i, rev, text in rows:
            if text is None:
                out.append(held[i])
                continue
            if isinstance(text, TrackTail):
                track = held[i].extended(rev, text)
                n_tails += 1
            else:
                track = CachedTrack.decode(i, rev, text)
            out.append(track)
            fresh.append(track)
        with self._lock:
            self.hits += len(out) - len(fresh)
            self.misses += len(fresh)
            self.tails += n_tails
            for track in out:
                if self._tracks.get(track.id) is track:
                    self._tracks.move_to_end(track.id)
            for track in fresh:
                now = self._tracks.get(track.id)
                if now is None or now.rev <= track.rev:  # never replace a newer version
                    self._put(track)
        return out

    def _put(self, track: CachedTrack) -> None:
        old = self._tracks.pop(track.id, None)
        if old is not None:
            self.nbytes -= old.nbytes
        if track.nbytes > self.max_bytes:
            return
        self._tracks[track.id] = track
        self.nbytes += track.nbytes
        while self.nbytes > self.max_bytes:
            _, gone = self._tracks.popitem(last=False)
            self.nbytes -= gone.nbytes

    def clear(self) -> None:
        """Forget every body."""
        with self._lock:
            self._tracks.clear()
            self.nbytes = 0
