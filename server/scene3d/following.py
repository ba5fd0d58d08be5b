"""Following a track: which clients' cameras look at which track's head, and aiming them.

:meth:`Scene3D.follow` (``PUT /api/scene3d/follow``, sent by the console when the operator
selects a track) points clients' cameras at the track's newest position and keeps them
there as new points arrive: a camera keeps its offset from the look-at point (so an
operator who orbits or zooms keeps that view), starting from :data:`FOLLOW_OFFSET_M`
behind the track's recent heading. Followed tracks (of the broadcast and of sessions with
a connected client) are drawn thick and yellow; each following client gets its own marker
and the track's id at the head (client-scoped nodes). ``follow(None)`` stops.

``follow(id, session=s)`` moves the cameras of session ``s`` only (see
:mod:`.connections`); ``follow(id)`` without a session is the broadcast: every client
follows ``id`` and the sessions' own choices are dropped. A session's ``None`` stops its
clients only (it also shadows a broadcast choice). A client that connects while its
session (or the broadcast) follows a track starts at the track's head.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .geometry import _LIFT_M
from .style import _FOLLOW_COLOUR
from .tracks import TrackLayer

__all__ = ["FOLLOW_OFFSET_M", "FollowController", "follow_offset"]

log = logging.getLogger("demtrack.server")

#: Where a camera starts when it begins to follow: this far behind the track (m,
#: horizontally) and this far above its newest point.
FOLLOW_OFFSET_M = (60.0, 35.0)
#: Most sessions whose follow choice is kept (the oldest choice goes first).
_MAX_SESSIONS = 256
#: How long (s) a client just aimed is aimed again until it reports looking at the target
#: (a camera report it sent before our move can land after it and undo it on our side).
_SETTLE_S = 20.0


def follow_offset(
    points: np.ndarray, back_m: float = FOLLOW_OFFSET_M[0], up_m: float = FOLLOW_OFFSET_M[1]
) -> np.ndarray:
    """A camera offset from a track's newest point: behind its recent heading, above it.

    Parameters
    ----------
    points : ndarray, shape (k, 3)
        The track's points in time order, site frame (m).
    back_m, up_m : float
        Horizontal distance behind and height above the newest point (m).

    Returns
    -------
    ndarray, shape (3,)
        ``camera position - look_at`` (site frame, m). The heading is that of the last
        point at least 2 m (horizontally) before the newest; a track that has not moved
        that far is looked at from the south.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    heading = np.array([0.0, 1.0])
    if len(p) >= 2:
        d = p[-1, :2] - p[:-1, :2]
        far = np.flatnonzero(np.hypot(d[:, 0], d[:, 1]) >= 2.0)
        if len(far):
            v = d[far[-1]]
            heading = v / np.hypot(v[0], v[1])
    return np.array([-back_m * heading[0], -back_m * heading[1], up_m])


@dataclass
class _Follow:
    """One follow choice: of a session, or the broadcast one (key None)."""

    track_id: int | None  # None: this session stopped (shadows a broadcast choice)
    target: np.ndarray | None = None  # look-at point last aimed at
    offset: np.ndarray | None = None  # where cameras that start following are put


class FollowController:
    """The follow choices of sessions and the broadcast, and the cameras they move.

    Everything but :meth:`ask`, :meth:`state`, :meth:`connected` and :meth:`disconnected`
    runs on the scene thread.

    Parameters
    ----------
    server : viser.ViserServer
        Its clients are aimed.
    tracks : TrackLayer
        The scene's tracks: their heads are followed, the followed ones highlighted.
    load_track : callable
        Takes a track body (all its points) the scene has not been sent yet.

    Attributes
    ----------
    follows : dict
        Follow choices by session (None: the broadcast one); the scene thread's own.
    asked : dict
        The latest choices asked for (the scene thread applies them on its next pass).
    client_session : dict
        Each connected client's session (None: it joined none), set when it connects.
    markers : dict
        Each following client's own head marker and label (client-scoped nodes).
    unsettled : dict
        Clients aimed but not yet seen looking at the target: id -> (target, offset,
        monotonic deadline or None before the client's first report since the move; the
        move's time is in ``aimed_at``). The scene thread's own.
    aimed_at : dict
        Wall-clock time of each client's latest move by us (kept once it settled).
    home : tuple of ndarray or None
        Every client's starting view (``initial_camera``: position, look-at), set with it.
    """

    def __init__(
        self, server: Any, tracks: TrackLayer, load_track: Callable[[dict[str, Any]], None]
    ) -> None:
        self.server = server
        self.tracks = tracks
        self.load_track = load_track
        self.follows: dict[str | None, _Follow] = {}
        self.asked: dict[str | None, int | None] = {}
        self.client_session: dict[int, str | None] = {}
        self.markers: dict[int, tuple[Any, Any]] = {}
        self.unsettled: dict[int, tuple[np.ndarray, np.ndarray, float | None]] = {}
        self.aimed_at: dict[int, float] = {}
        self.home: tuple[np.ndarray, np.ndarray] | None = None
        self._aim_lock = threading.Lock()

    # ------------------------------------------------------------- any thread
    def ask(self, track_id: int | None, session: str | None) -> None:
        """Note a choice asked for (any thread), so that :meth:`state` reports it at once."""
        if session is None:
            self.asked.clear()
        else:
            self.asked.pop(session, None)
            while len(self.asked) >= _MAX_SESSIONS:
                oldest = next((k for k in self.asked if k is not None), None)
                if oldest is None:
                    break
                del self.asked[oldest]
        self.asked[session] = track_id

    def state(self, session: str | None = None) -> dict[str, Any]:
        """The followed track, the point the cameras look at, and the clients' cameras.

        See :meth:`Scene3D.follow_state`.
        """
        asked = dict(self.asked)
        track_id = asked[session] if session in asked else asked.get(None)
        rec = self._effective(session)
        target = None if rec is None or rec.track_id != track_id else rec.target
        clients = []
        for cid, client in sorted(self.server.get_clients().items()):
            mine = self.client_session.get(cid)
            if session is not None and mine != session:
                continue
            followed = self._effective(mine)
            cam = client.camera
            clients.append(
                {
                    "id": int(cid),
                    "session": mine,
                    "track_id": None if followed is None else followed.track_id,
                    "look_at_enu": [float(x) for x in cam.look_at],
                    "position_enu": [float(x) for x in cam.position],
                }
            )
        return {
            "track_id": track_id,  # the choice as asked: read-your-writes
            "look_at_enu": None if target is None else [float(x) for x in target],
            "clients": clients,
        }

    def connected(self, client_id: int, session: str | None) -> None:
        """Note a new client's session (viser's connect callback)."""
        self.client_session[client_id] = session

    def disconnected(self, client_id: int) -> None:
        """Forget a client that left (viser's disconnect callback)."""
        self.client_session.pop(client_id, None)
        self.markers.pop(client_id, None)  # its nodes went with it

    # ----------------------------------------------------------- scene thread
    def _effective(self, session: str | None) -> _Follow | None:
        """The follow choice a client of ``session`` obeys (its own, else the broadcast)."""
        rec = None if session is None else self.follows.get(session)
        return rec if rec is not None else self.follows.get(None)

    def followed_ids(self) -> set[int]:
        """Every followed track (kept from pruning)."""
        return {f.track_id for f in list(self.follows.values()) if f.track_id is not None}

    def restyle(self) -> None:
        """Highlight the tracks someone looks at: the broadcast's and connected sessions'.

        A session whose page is gone (or has not opened its 3D view) keeps its choice for
        clients that connect later but does not colour the scene for everyone else.
        """
        present = set(list(self.client_session.values()))
        now = {
            f.track_id
            for k, f in list(self.follows.items())
            if f.track_id is not None and (k is None or k in present)
        }
        self.tracks.highlight(now)

    def on_follow(
        self, track_id: int | None, body: dict[str, Any] | None, session: str | None
    ) -> None:
        """Apply a choice asked for with :meth:`Scene3D.follow`."""
        if session is None:
            self.follows.clear()  # the broadcast: every client, sessions' choices go
            if track_id is not None:
                self.follows[None] = _Follow(track_id)
        else:
            self.follows.pop(session, None)
            # A session's stop is kept only while it has a broadcast choice to shadow.
            if track_id is not None or None in self.follows:
                self.follows[session] = _Follow(track_id)
            sessions = [k for k in self.follows if k is not None]
            for k in sessions[: max(0, len(sessions) - _MAX_SESSIONS)]:
                del self.follows[k]
        self.restyle()
        if track_id is not None:
            known = self.tracks.tracks.get(track_id)
            if body is not None and int(body["id"]) == track_id:
                n = len(body.get("points") or [])
                if known is None or n > len(known.points):
                    self.load_track({**body, "first_index": 0})
        # Clients that follow nothing now lose their marker; cameras stay where they are.
        for cid in list(self.markers):
            rec = self._effective(self.client_session.get(cid))
            if rec is None or rec.track_id is None:
                self._drop_marker(cid)

    def on_client(self, client: Any) -> None:
        """A client that connects while its session follows a track starts looking at it."""
        cid = int(client.client_id)
        if cid not in self.client_session:
            return  # gone already
        self.restyle()
        rec = self._effective(self.client_session.get(cid))
        if rec is None or rec.track_id is None or rec.target is None or rec.offset is None:
            return
        self._aim([client], rec.target, rec.offset, keep_offset=False)
        self._mark(client, rec.track_id, rec.target)

    def update(self) -> None:
        """Aim each follow choice's clients at its track's newest point, if it moved."""
        if not self.follows:
            return
        groups: dict[str | None, list[Any]] = {}
        present = self.server.get_clients()
        for cid, client in present.items():
            session = self.client_session.get(cid)
            key = session if session is not None and session in self.follows else None
            groups.setdefault(key, []).append(client)
        for cid in [c for c in self.unsettled if c not in present]:
            del self.unsettled[cid]  # gone
        for cid in [c for c in self.aimed_at if c not in present]:
            del self.aimed_at[cid]
        for key, rec in list(self.follows.items()):
            pts = self.tracks.points_of(rec.track_id)
            if rec.track_id is None or pts is None:
                continue
            target = pts[-1] + [0.0, 0.0, _LIFT_M]
            first = rec.offset is None
            if (
                rec.offset is not None
                and rec.target is not None
                and np.allclose(target, rec.target)
            ):
                self._settle(groups.get(key, []), rec.target, rec.offset)
                continue
            start = follow_offset(pts) if rec.offset is None else rec.offset
            rec.offset, rec.target = start, target
            members = groups.get(key, [])
            self._aim(members, target, start, keep_offset=not first)
            for client in members:
                self._mark(client, rec.track_id, target)

    def _aim(
        self, clients: list[Any], target: np.ndarray, start: np.ndarray, keep_offset: bool
    ) -> None:
        """Point ``clients``' cameras at ``target`` from their own offset or from ``start``."""
        with self._aim_lock:
            for client in clients:
                cam = client.camera
                try:
                    offset = start
                    # viser's getters raise until the client has sent its camera once:
                    # read them only to keep an offset, never to start from ``start``
                    if keep_offset:
                        with contextlib.suppress(AssertionError):
                            own = np.asarray(cam.position) - np.asarray(cam.look_at)
                            if np.all(np.isfinite(own)) and own.any():
                                offset = own
                    with client.atomic():
                        cam.up_direction = (0.0, 0.0, 1.0)
                        cam.position = tuple(float(x) for x in target + offset)
                        cam.look_at = tuple(float(x) for x in target)
                except Exception:  # noqa: BLE001 - a client that left meanwhile
                    log.debug("could not move client %s's camera", client.client_id)
                    offset = start
                # viser stamps our moves with the wall clock, and each client report too;
                # the settling time starts at the first report after this move
                self.unsettled[int(client.client_id)] = (target, offset, None)
                self.aimed_at[int(client.client_id)] = time.time()

    def _settle(self, clients: list[Any], target: np.ndarray, offset: np.ndarray) -> None:
        """Aim again those of ``clients`` whose reports since their aim missed it.

        viser keeps the camera a client last reported: a report the client sent before
        our move reached it can arrive after the move and put the camera (on our side,
        and so the offset kept next) back where it was. A client is aimed again until one
        of its reports looks at ``target`` (or :data:`_SETTLE_S` pass after its first
        report since the first aim); from then on it is left alone, so that the operator
        can look around. A client that reports the starting view (``initial_camera``)
        after our latest move is aimed again at any time: its viewer started afresh (a
        slow page can do so long after connecting), and no operator pan ends exactly
        there. ``offset``: the follow's camera offset, for a client aimed afresh.
        """
        now = time.monotonic()
        for client in clients:
            cid = int(client.client_id)
            cam = client.camera
            try:
                reported = cam.update_timestamp
                looks = np.allclose(cam.look_at, target, rtol=0.0, atol=1e-3)
                home = self._at_home(cam)
            except AssertionError:  # no report at all yet
                continue
            if reported <= self.aimed_at.get(cid, 0.0):
                continue  # no report since our move: the camera is still ours
            pending = self.unsettled.get(cid)
            if pending is not None and not np.allclose(pending[0], target):
                self.unsettled.pop(cid, None)
                pending = None
            if pending is None:
                if home and not looks:
                    self._aim([client], target, offset, keep_offset=False)
                continue
            deadline = pending[2] if pending[2] is not None else now + _SETTLE_S
            if looks or (now > deadline and not home):
                self.unsettled.pop(cid, None)
                continue
            self._aim([client], target, pending[1], keep_offset=False)  # records a new move
            self.unsettled[cid] = (*self.unsettled[cid][:2], deadline)  # the first's end

    def _at_home(self, cam: Any) -> bool:
        """Whether ``cam`` (a client's reported camera) is the starting view."""
        if self.home is None:
            return False
        pos, look = self.home
        return bool(
            np.allclose(cam.position, pos, rtol=0.0, atol=1e-6)
            and np.allclose(cam.look_at, look, rtol=0.0, atol=1e-6)
        )

    def _mark(self, client: Any, track_id: int, target: np.ndarray) -> None:
        """Put ``client``'s own head marker and label at ``target`` (client-scoped nodes)."""
        try:
            head = client.scene.add_icosphere(
                "/follow/head", radius=1.2, color=_FOLLOW_COLOUR, position=target
            )
            label = client.scene.add_label(
                "/follow/label", f"#{track_id}", position=target + [0.0, 0.0, 3.0]
            )
        except Exception:  # noqa: BLE001 - a client that left meanwhile
            log.debug("could not mark client %s's followed track", client.client_id)
            return
        self.markers[int(client.client_id)] = (head, label)

    def _drop_marker(self, client_id: int) -> None:
        handles = self.markers.pop(client_id, None)
        for h in handles or ():
            with contextlib.suppress(Exception):  # the client may have left
                h.remove()
