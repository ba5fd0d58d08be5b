"""Track rows and ``track_update`` bodies: only what changed is converted and encoded.

Per track the pipeline keeps its positions as last sent, their JSON point dicts and
those dicts encoded; a changed track's stored row is re-assembled from the encoded
points, and the store rewrites its points only from the first that changed
(``points_from``). New points of every changed track go through one geodetic conversion
per batch (each costs a pyproj round trip), which also fills the batch's fix hits.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from demtrack.core.activity.kinds import EventKind
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.tracking.types import Track

from ..store.codec import dumps_json
from .events import track_event
from .stream_messages import StreamPayload, TrackUpdatePayload

__all__ = ["BodyOf", "Geodetic", "TrackBodies"]

#: ``(points (k, 3), dicts)``: dicts that get the points' ``lat_deg``, ``lon_deg``, ``h_m``.
Geodetic = tuple[np.ndarray, list[dict[str, Any]]]
#: ``body_of(track, live, first_index)``: a track's JSON body from ``first_index`` on.
BodyOf = Callable[[Track, bool, int], dict[str, Any]]


class TrackBodies:
    """The cached JSON of the tracks sent (see the module docstring).

    Attributes
    ----------
    points : dict
        Per track id: ``(positions (n, 3) as last sent, point dicts, their JSON texts)``.
    dirty_from : dict of int to int
        Per track id: the first point index whose encoding changed since its row was
        last stored; cleared once a write commits (:meth:`stored`).
    seen : dict
        Per track id: ``(n_points, tail bytes, live)`` as last sent.
    live_ids : set of int
        The tracker's live tracks at the last :meth:`changes`.
    """

    def __init__(self, frame: LocalFrame) -> None:
        self.frame = frame
        self.points: dict[int, tuple[np.ndarray, list[dict[str, Any]], list[str]]] = {}
        self.dirty_from: dict[int, int] = {}
        self.seen: dict[int, tuple[int, bytes, bool]] = {}
        self.live_ids: set[int] = set()

    def forget(self, ids: Sequence[int]) -> None:
        """Drop what is kept of tracks ``ids`` (the tracker forgot them)."""
        for i in ids:
            self.seen.pop(i, None)
            self.points.pop(i, None)
            self.dirty_from.pop(i, None)

    def stored(self, rows: Sequence[dict[str, Any]]) -> None:
        """Track ``rows`` were written: their points are clean."""
        for r in rows:
            self.dirty_from.pop(r["id"], None)

    def sent_since(self, ids: set[int]) -> float:
        """The earliest newest-point time of the tracks ``ids`` as last sent (-inf if unknown).

        A track only gains points, so its final form ends at or after that time: reading
        the ended tracks from there on avoids rebuilding every track the session ever had.
        """
        ends = [self.points[i][1][-1]["t_s"] for i in ids if i in self.points and self.points[i][1]]
        return min(ends) if len(ends) == len(ids) else -math.inf

    def refresh(self, tracks: Sequence[Track], also_geodetic: Sequence[Geodetic] = ()) -> None:
        """Bring the cached JSON points of ``tracks`` up to date.

        Only points that changed since the last call are converted and encoded (a track
        changes at its end), and the new points of all ``tracks`` go through one geodetic
        conversion. ``also_geodetic``: pairs whose dicts get their points' geodetic fields
        from that same conversion (PROJ converts each point on its own, so the values are
        those of a call of their own).
        """
        todo = []
        for track in tracks:
            p = track.p_enu
            cached = self.points.get(track.id)
            if cached is not None and cached[0] is p:
                continue  # the same Track value as last time (its positions array is cached)
            same = 0
            if cached is not None:
                old_p, old_pts, old_js = cached
                m = min(len(old_p), len(p))
                diff = np.flatnonzero(np.any(old_p[:m] != p[:m], axis=1))
                same = int(diff[0]) if len(diff) else m
                same = min(same, len(old_pts))
                if same == len(p) == len(old_pts):
                    continue  # nothing changed
                pts, js = old_pts[:same], old_js[:same]
            else:
                pts, js = [], []
            todo.append((track, same, pts, js))
            self.dirty_from[track.id] = min(same, self.dirty_from.get(track.id, same))
        if not todo and not also_geodetic:
            return
        parts = [t.p_enu[same:] for t, same, _, _ in todo]
        n_track = sum(len(a) for a in parts)
        q = np.concatenate(parts + [a for a, _ in also_geodetic])
        lat, lon, h = (
            np.atleast_1d(a).tolist() for a in self.frame.to_geodetic(q[:, 0], q[:, 1], q[:, 2])
        )
        k = n_track
        for _, dicts in also_geodetic:
            for d in dicts:
                d["lat_deg"], d["lon_deg"], d["h_m"] = lat[k], lon[k], h[k]
                k += 1
        rows = q[:n_track].tolist()
        k = 0
        for track, same, pts, js in todo:
            for tp in track.points[same:]:
                e, n, u = rows[k]
                pts.append(
                    {
                        "t_s": tp.t_s,
                        "e_m": e,
                        "n_m": n,
                        "u_m": u,
                        "lat_deg": lat[k],
                        "lon_deg": lon[k],
                        "h_m": h[k],
                        "sensors": list(tp.sensors),
                        "detection_ids": list(tp.fix_indices),
                    }
                )
                js.append(dumps_json(pts[-1]))
                k += 1
            self.points[track.id] = (track.p_enu, pts, js)

    def body(self, track: Track, live: bool, first_index: int = 0) -> dict[str, Any]:
        """JSON body of a track, points from ``first_index`` on."""
        self.refresh([track])
        points = self.points[track.id][1][first_index:]
        return {
            "id": track.id,
            "cls": track.cls,
            "sensors": sorted(track.sensors),
            "gaps": [list(g) for g in track.gaps],
            "live": live,
            "n_points": len(track.points),
            "first_index": first_index,
            "points": points,
        }

    def changes(
        self,
        tracks: Sequence[Track],
        live_ids: set[int],
        lag: int,
        body_of: BodyOf,
        *,
        force: bool = False,
        also_geodetic: Sequence[Geodetic] = (),
    ) -> tuple[list[dict[str, Any]], list[tuple[str, StreamPayload]]]:
        """Of ``tracks``, those that changed since the last call: table rows and messages.

        ``live_ids``: the tracker's live tracks; ``lag``: its smoothing lag (points
        revised after they were sent); ``body_of``: a track's body (:meth:`body`, or the
        pipeline's hook around it). ``force``: every track's whole row, no messages (the
        start-up rewrite).
        """
        self.live_ids = live_ids
        rows: list[dict[str, Any]] = []
        events: list[tuple[str, StreamPayload]] = []
        changed = []
        for track in tracks:
            if not track.points:
                continue
            live = track.id in live_ids
            p = track.p_enu
            sig = (len(track.points), p[-(lag + 1) :].tobytes(), live)
            prev = self.seen.get(track.id)
            if prev == sig and not force:
                continue
            self.seen[track.id] = sig
            changed.append((track, live, p, prev))
        self.refresh([t for t, _, _, _ in changed], also_geodetic)
        for track, live, p, prev in changed:
            full = body_of(track, live, 0)
            start = 0 if force else self.dirty_from.get(track.id, len(track.points))
            rows.append(
                {
                    "id": track.id,
                    "cls": track.cls,
                    "t_start": track.points[0].t_s,
                    "t_end": track.points[-1].t_s,
                    "e_min": float(p[:, 0].min()),
                    "n_min": float(p[:, 1].min()),
                    "e_max": float(p[:, 0].max()),
                    "n_max": float(p[:, 1].max()),
                    "sensors": sorted(track.sensors),
                    "live": live,
                    "body": dumps_json({k: v for k, v in full.items() if k != "points"}),
                    "points_from": start,
                    "point_texts": self.points[track.id][2][start:],
                }
            )
            if not live:
                self.points.pop(track.id, None)  # ended: no more changes expected
            if force:
                continue
            first = 0 if prev is None else max(0, min(prev[0], len(track.points)) - lag - 1)
            tail = dict(full, first_index=first, points=full["points"][first:])
            events.append(("track_update", TrackUpdatePayload(track=tail)))
            if prev is None:
                events.append(("event", track_event(EventKind.TRACK_CONFIRMED, track, self.frame)))
            elif prev[2] and not live:
                events.append(("event", track_event(EventKind.TRACK_ENDED, track, self.frame)))
        return rows, events
