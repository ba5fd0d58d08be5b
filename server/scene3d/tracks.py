"""The live tracks: each track's points from ``track_update`` messages, drawn as polylines.

A track is a polyline in its class's colour (:func:`~.style.class_colour`, as on the
map; ended tracks dimmed,
followed ones thick and yellow) 0.4 m above its points, drawn in pieces of
:data:`_PIECE_SEGMENTS` segments (``/tracks/{id}/{k}``). At most :data:`_MAX_TRACKS` are
kept: the ended ones seen longest ago go first, followed ones never.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .geometry import _LIFT_M, polyline_segments
from .style import _FOLLOW_COLOUR, class_colour

__all__ = ["TrackLayer"]

_MAX_TRACKS = 40
#: Segments per drawn piece of a track's polyline (see :meth:`TrackLayer._draw`).
_PIECE_SEGMENTS = 256


@dataclass
class _Track:
    id: int
    cls: str
    live: bool
    points: list[tuple[float, float, float]] = field(default_factory=list)
    det_ids: list[list[int]] = field(default_factory=list)
    t_last: float = 0.0
    #: The first point index changed since the track was last drawn.
    changed_from: int = 0
    #: Polyline pieces drawn (``/tracks/{id}/{k}``) and the ``(colour, thickness)`` used.
    n_drawn: int = 0
    style: tuple[tuple[int, int, int], float] | None = None


class TrackLayer:
    """The tracks the scene has been sent, and their drawing.

    Parameters
    ----------
    server : viser.ViserServer
        Where the tracks are drawn.
    nodes : dict
        Scene node name -> viser handle, shared with the scene: drawn nodes go in.

    Attributes
    ----------
    tracks : dict
        Track id -> its points and drawing state.
    dirty : set of int
        Tracks to redraw on the next :meth:`render`.
    highlighted : set of int
        Tracks drawn as followed (see :meth:`highlight`).
    """

    def __init__(self, server: Any, nodes: dict[str, Any]) -> None:
        self.server = server
        self.nodes = nodes
        self.tracks: dict[int, _Track] = {}
        self.dirty: set[int] = set()
        self.highlighted: set[int] = set()

    def update(self, body: dict[str, Any]) -> None:
        """Apply a track body: its points from ``first_index`` on replace those kept.

        Parameters
        ----------
        body : dict
            A ``track_update`` message's track (``id``, ``cls``, ``live``,
            ``first_index``, ``points`` with ``t_s, e_m, n_m, u_m, detection_ids``).
            A ``first_index`` past the points kept (a missed update) appends.
        """
        tid = int(body["id"])
        tr = self.tracks.get(tid)
        if tr is None:
            tr = self.tracks[tid] = _Track(tid, str(body["cls"]), bool(body["live"]))
        first = int(body.get("first_index", 0))
        if first > len(tr.points):  # a missed update: keep what we have, append the rest
            first = len(tr.points)
        pts = body.get("points") or []
        del tr.points[first:], tr.det_ids[first:]
        tr.changed_from = min(tr.changed_from, first)
        for p in pts:
            tr.points.append((p["e_m"], p["n_m"], p["u_m"]))
            tr.det_ids.append([int(i) for i in p.get("detection_ids", [])])
        tr.live = bool(body["live"])
        if pts:
            tr.t_last = float(pts[-1]["t_s"])
        self.dirty.add(tid)

    def points_of(self, track_id: int | None) -> np.ndarray | None:
        """A track's points, shape ``(k, 3)`` (site frame, m), or None if it has none."""
        tr = None if track_id is None else self.tracks.get(track_id)
        if tr is None or not tr.points:
            return None
        return np.asarray(tr.points, dtype=np.float64)

    def highlight(self, track_ids: set[int]) -> None:
        """Draw ``track_ids`` as followed from the next :meth:`render` on (and no others)."""
        self.dirty |= track_ids ^ self.highlighted  # their colour and thickness change
        self.highlighted = track_ids

    def render(self, keep: Callable[[], set[int]]) -> None:
        """Prune and redraw the tracks that changed.

        Parameters
        ----------
        keep : callable
            The ids never to prune (the followed tracks), asked only when pruning.
        """
        if not self.dirty:
            return
        self._prune(keep)
        for tid in sorted(self.dirty):
            tr = self.tracks.get(tid)
            if tr is not None:
                self._draw(tr)
        self.dirty.clear()

    def _style(self, tr: _Track) -> tuple[tuple[int, int, int], float]:
        colour = class_colour(tr.cls)
        if tr.id in self.highlighted:
            return _FOLLOW_COLOUR, 7.0
        if tr.live:
            return colour, 4.0
        c_r, c_g, c_b = (int(0.5 * c + 64) for c in colour)
        return (c_r, c_g, c_b), 2.0

    def _draw(self, tr: _Track) -> None:
        """Redraw the pieces of ``tr``'s polyline its new points touched.

        The polyline is drawn in pieces of :data:`_PIECE_SEGMENTS` segments
        (``/tracks/{id}/{k}``): a live track changes at its end (new points, a smoothed
        tail), so an update re-sends one or two pieces rather than the whole history.
        A new colour or thickness (followed, ended) redraws every piece.
        """
        n = len(tr.points)
        n_pieces = 0 if n < 2 else (n - 2) // _PIECE_SEGMENTS + 1
        style = self._style(tr)
        # segment j joins points j and j + 1 and lies in piece j // _PIECE_SEGMENTS
        start = 0 if style != tr.style else max(tr.changed_from - 1, 0) // _PIECE_SEGMENTS
        for k in range(n_pieces, tr.n_drawn):
            handle = self.nodes.pop(f"/tracks/{tr.id}/{k}", None)
            if handle is not None:
                handle.remove()
        colour, thickness = style
        for k in range(start, n_pieces):
            a = k * _PIECE_SEGMENTS
            b = min(a + _PIECE_SEGMENTS, n - 1)
            p = np.asarray(tr.points[a : b + 1]) + [0.0, 0.0, _LIFT_M]
            name = f"/tracks/{tr.id}/{k}"
            self.nodes[name] = self.server.scene.add_line_segments(
                name,
                polyline_segments(p),
                colour,
                thickness=thickness,
                thickness_units="screen",
            )
        tr.n_drawn, tr.style, tr.changed_from = n_pieces, style, n

    def _prune(self, keep: Callable[[], set[int]]) -> None:
        if len(self.tracks) <= _MAX_TRACKS:
            return
        followed = keep()
        ended = sorted(
            (t for t in self.tracks.values() if not t.live and t.id not in followed),
            key=lambda t: t.t_last,
        )
        for tr in ended[: len(self.tracks) - _MAX_TRACKS]:
            del self.tracks[tr.id]
            self.dirty.discard(tr.id)
            for k in range(tr.n_drawn):
                handle = self.nodes.pop(f"/tracks/{tr.id}/{k}", None)
                if handle is not None:
                    handle.remove()
