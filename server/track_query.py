"""Which stored tracks a request asks for: time window, class, sensor and box filters.

Shared by ``GET /api/tracks``, its export and ``GET /api/synopsis``. Tracks come from the
server's :class:`~demtrack.server.track_cache.TrackCache`; their points are clipped to the
window. Bad filters raise :class:`~demtrack.core.errors.QueryError` (HTTP 422).
"""

from __future__ import annotations

from functools import partial
from typing import Any

from demtrack.core.errors import NotFoundError, QueryError

from .state import ConsoleState
from .track_cache import CachedTrack, TrackCache, clip

__all__ = [
    "check_window",
    "filter_tracks",
    "parse_bbox",
    "select_tracks",
    "stored_track",
    "track_cache",
]


def check_window(
    t_from: float | None, t_to: float | None, *, first: str = "t_from", second: str = "t_to"
) -> None:
    """:class:`QueryError` when both ends are given and the window ends before it starts.

    ``first``, ``second``: what the request calls the two ends (``t0``, ``t1`` for the
    synopsis).
    """
    if t_from is not None and t_to is not None and t_from > t_to:
        raise QueryError(f"{first} ({t_from}) is after {second} ({t_to})")


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    """``"e_min,n_min,e_max,n_max"`` (site frame, m) -> tuple; :class:`QueryError` if malformed."""
    if text is None:
        return None
    try:
        box = tuple(float(x) for x in text.split(","))
    except ValueError:
        box = ()
    if len(box) != 4 or not all(abs(x) < 1e12 for x in box) or box[0] > box[2] or box[1] > box[3]:
        raise QueryError(f"bbox must be 'e_min,n_min,e_max,n_max' (m, min <= max), got {text!r}")
    return box  # type: ignore[return-value]


def _in_box(track: dict[str, Any], box: tuple[float, float, float, float]) -> bool:
    return any(
        box[0] <= p["e_m"] <= box[2] and box[1] <= p["n_m"] <= box[3] for p in track["points"]
    )


def track_cache(state: ConsoleState) -> TrackCache:
    """The server's :class:`TrackCache` (one per app, over its store)."""
    cache: TrackCache = state.cached("track_cache", partial(TrackCache, state.store))
    return cache


def select_tracks(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    sensor: str | None,
    bbox: str | None,
) -> list[tuple[CachedTrack, dict[str, Any]]]:
    """Cached tracks passing every filter, each with its body clipped to the window.

    The clipped bodies share their point dicts and lists with the cache: read-only.
    """
    check_window(t_from, t_to)
    box = parse_bbox(bbox)
    out = []
    for track in track_cache(state).select(t_from=t_from, t_to=t_to, cls=cls, bbox=box):
        if sensor is not None and sensor not in track.body["sensors"]:
            continue
        clipped = clip(track, t_from, t_to)
        if not clipped["points"] or (box is not None and not _in_box(clipped, box)):
            continue
        out.append((track, clipped))
    return out


def filter_tracks(
    state: ConsoleState,
    t_from: float | None,
    t_to: float | None,
    cls: str | None,
    sensor: str | None,
    bbox: str | None,
) -> list[dict[str, Any]]:
    """Stored track bodies passing every filter, points clipped to the window.

    Read-only: the bodies share their point dicts and lists with the server's
    :class:`~demtrack.server.track_cache.TrackCache` (copy before changing anything).
    """
    return [clipped for _, clipped in select_tracks(state, t_from, t_to, cls, sensor, bbox)]


def stored_track(state: ConsoleState, track_id: int) -> dict[str, Any]:
    """The stored body of track ``track_id``; :class:`NotFoundError` when there is none."""
    body: dict[str, Any] | None = state.store.track(track_id)
    if body is None:
        raise NotFoundError(f"no track {track_id}")
    return body
