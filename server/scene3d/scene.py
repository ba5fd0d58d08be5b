"""The scene's lifecycle: the viser server, its update thread, and the stream it draws.

viser runs its own HTTP + WebSocket server (its web client ships in the wheel) on its own
port, bound to the API's host. :class:`Scene3D` starts it, builds the static scene
(:mod:`.static`) on its own thread and then follows the same stream messages the
WebSocket sends (the pipeline's publisher is fanned out to :meth:`Scene3D.publish`),
drawing the rays (:mod:`.rays`) and tracks (:mod:`.tracks`) and moving the cameras of
those following a track (:mod:`.following`) at most every ``update_s``.
"""

from __future__ import annotations

import collections
import contextlib
import io
import logging
import threading
from typing import Any

import numpy as np

from demtrack.core.site.folder import Site

from .connections import (
    _SESSION_RE,
    SESSION_PATTERN,
    SessionGate,
    display_host,
    session_of_path,
    websocket_path,
)
from .following import FollowController
from .frusta import FrustumPoses
from .rays import RayLayer
from .static import build_static, configure_gui
from .tracks import TrackLayer

__all__ = ["Scene3D"]

log = logging.getLogger("demtrack.server")


class Scene3D:
    """The viser server and its scene, updated from stream messages.

    Parameters
    ----------
    site : Site
    host : str
        Address to bind (the API's host).
    port : int
        Port (0 = any free one; viser also moves off a busy port).
    max_rays : int
        Newest viewing rays kept.
    mesh_side : int
        Most terrain vertices per side.
    texture_px : int
        Largest side of the orthophoto texture (px).
    update_s : float
        Shortest time (s) between two drawing passes.
    require_session : bool
        Admit only viser clients whose WebSocket path names a session registered with
        :meth:`admit` (what the console's operator token buys); False admits every client.

    Attributes
    ----------
    server : viser.ViserServer
    url : str
        ``http://host:port/`` of the scene.
    nodes : dict
        Scene node name -> viser handle of what this class added.
    """

    def __init__(
        self,
        site: Site,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        max_rays: int = 40,
        mesh_side: int = 250,
        texture_px: int = 2048,
        update_s: float = 0.25,
        require_session: bool = True,
    ) -> None:
        import viser

        self.site = site
        self.max_rays = max_rays
        self.mesh_side = mesh_side
        self.texture_px = texture_px
        self.update_s = update_s
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints a banner: we print URLs
            self.server = viser.ViserServer(host=host, port=port, label="demtrack", verbose=False)
        self.url = f"http://{display_host(host)}:{self.server.get_port()}/"
        configure_gui(self.server)
        self.gate = SessionGate(self.server, required=require_session)
        self.nodes: dict[str, Any] = {}
        self.n_messages = 0
        self.n_dropped = 0
        self.error: BaseException | None = None
        self._inbox: collections.deque[dict[str, Any]] = collections.deque()
        self._inbox_max = 20_000
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._rays = RayLayer(self.server, site.sensors, self.nodes, max_rays)
        self._tracks = TrackLayer(self.server, self.nodes)
        #: PTZ frusta: each sensor's newest pose, applied once per render.
        self.poses = FrustumPoses(site.sensors, self.nodes)
        self._following = FollowController(self.server, self._tracks, self._on_track)
        self.server.on_client_connect(self._on_client_connect)
        self.server.on_client_disconnect(self._on_client_disconnect)
        self._thread = threading.Thread(target=self._run, name="demtrack-scene3d", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- public
    def publish(self, messages: list[dict[str, Any]]) -> None:
        """Queue stream messages (any thread; never blocks). The oldest drop when full."""
        for m in messages:
            if m.get("type") in ("fix", "track_update", "sensor_pose"):
                if len(self._inbox) >= self._inbox_max:
                    self._inbox.popleft()
                    self.n_dropped += 1
                self._inbox.append(m)
        self._wake.set()

    def follow(
        self,
        track_id: int | None,
        track: dict[str, Any] | None = None,
        session: str | None = None,
    ) -> None:
        """Follow a track with the cameras of a session's clients (``None`` stops).

        Parameters
        ----------
        track_id : int or None
        track : dict, optional
            The track's body as ``/api/tracks`` gives it (all points), for a track this
            scene has not been sent yet (it only sees the stream since it started).
            Later ``track_update`` messages keep it current.
        session : str, optional
            A follow session (:data:`SESSION_PATTERN`): only its clients move. Without
            one, every client follows and the sessions' own choices are dropped.

        Raises
        ------
        ValueError
            For a malformed session id.
        """
        if session is not None and not _SESSION_RE.match(session):
            raise ValueError(f"bad follow session {session!r}: want {SESSION_PATTERN}")
        tid = None if track_id is None else int(track_id)
        self._following.ask(tid, session)
        self._inbox.append({"type": "_follow", "track_id": tid, "track": track, "session": session})
        self._wake.set()

    def admit(self, session: str) -> None:
        """Let the viser clients of ``session`` see the scene (ValueError if malformed)."""
        self.gate.admit(session)

    def follow_state(self, session: str | None = None) -> dict[str, Any]:
        """The followed track, the point the cameras look at, and the clients' cameras.

        Parameters
        ----------
        session : str, optional
            Report this session's choice and clients; without one, the broadcast choice
            and every client.

        Returns
        -------
        dict
            ``track_id`` (or None; the latest choice asked for, reported at once while the
            scene applies it on its next pass), ``look_at_enu`` (the followed track's
            newest point, site frame m, or None before it has one), ``clients``:
            ``[{id, session, track_id, look_at_enu, position_enu}]`` as each connected
            viser client last reported or was sent (``track_id``: what it follows).
        """
        return self._following.state(session)

    def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Wait until the static scene (terrain, cameras, roads) is built."""
        return self._ready.wait(timeout_s)

    def flush(self, timeout_s: float = 10.0) -> bool:
        """Wait until every queued message has been drawn (for tests)."""
        done = threading.Event()
        self._inbox.append({"type": "_flush", "event": done})
        self._wake.set()
        return done.wait(timeout_s)

    def stop(self) -> None:
        """Stop the updater and the viser server."""
        self._stop.set()
        self._wake.set()
        self._thread.join(10.0)
        self.server.stop()

    # ------------------------------------------------- follow state, for tests
    @property
    def _client_session(self) -> dict[int, str | None]:
        """Each connected client's session (see :class:`.following.FollowController`)."""
        return self._following.client_session

    @property
    def _markers(self) -> dict[int, tuple[Any, Any]]:
        """Each following client's head marker and label."""
        return self._following.markers

    @property
    def _unsettled(self) -> dict[int, tuple[np.ndarray, np.ndarray, float | None]]:
        """Clients aimed but not yet seen looking at their target."""
        return self._following.unsettled

    # ------------------------------------------------------------------- live
    def _run(self) -> None:
        try:
            self._following.home = build_static(
                self.server,
                self.site,
                self.nodes,
                mesh_side=self.mesh_side,
                texture_px=self.texture_px,
            )
            self._ready.set()
            while not self._stop.is_set():
                self._wake.wait(self.update_s)
                self._wake.clear()
                flushes = self._drain()
                self._render()
                for ev in flushes:
                    ev.set()
                if not self._stop.is_set():
                    self._stop.wait(self.update_s)  # draw at most every update_s
        except BaseException as exc:  # noqa: BLE001 - a dead scene must not take the server
            self.error = exc
            log.exception("3D scene stopped")
        finally:
            self._ready.set()

    def _drain(self) -> list[threading.Event]:
        flushes = []
        while self._inbox:
            m = self._inbox.popleft()
            kind = m.get("type")
            if kind == "fix":
                self._rays.add_fix(m["fix"])
            elif kind == "track_update":
                self._on_track(m["track"])
            elif kind == "sensor_pose":
                self.poses.offer(m)
            elif kind == "_follow":
                self._following.on_follow(m["track_id"], m.get("track"), m.get("session"))
            elif kind == "_client":
                self._following.on_client(m["client"])
            elif kind == "_client_left":
                self._following.restyle()
            elif kind == "_flush":
                flushes.append(m["event"])
            self.n_messages += 1
        return flushes

    def _on_track(self, body: dict[str, Any]) -> None:
        self._tracks.update(body)
        # The tracker's choice among a ray's hits: the one nearest the point it made.
        self._rays.choose(body.get("points") or [])

    def _render(self) -> None:
        self.poses.render()
        self._rays.render()
        self._tracks.render(self._following.followed_ids)
        self._following.update()

    def _on_client_connect(self, client: Any) -> None:
        """Note a new client's session; the scene thread aims it on its next pass."""
        cid = int(client.client_id)
        self._following.connected(cid, session_of_path(websocket_path(self.server, cid)))
        self._inbox.append({"type": "_client", "client": client})
        self._wake.set()

    def _on_client_disconnect(self, client: Any) -> None:
        self._following.disconnected(int(client.client_id))
        self._inbox.append({"type": "_client_left"})
        self._wake.set()
