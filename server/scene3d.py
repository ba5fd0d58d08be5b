"""The viser 3D scene: terrain, cameras, roads, and the live rays, hits and tracks.

viser runs its own HTTP + WebSocket server (its web client ships in the wheel) on its own
port, bound to the API's host. The static scene is the DEM as a mesh (decimated to a few
hundred vertices a side) textured with the orthophoto, each sensor's camera as a frustum
at its pose with its still on the image plane, and the road centre lines draped on the
DEM. The live part follows the same stream messages the WebSocket sends (the pipeline's
publisher is fanned out to :meth:`Scene3D.publish`): for each new fix its viewing ray
with every terrain hit marked (the newest ``max_rays`` rays are kept), the hit the
tracker used highlighted, and each track as a coloured polyline.

**Following a track.** :meth:`Scene3D.follow` (``PUT /api/scene3d/follow``, sent by the
console when the operator selects a track) points clients' cameras at the track's newest
position and keeps them there as new points arrive: a camera keeps its offset from the
look-at point (so an operator who orbits or zooms keeps that view), starting from
:data:`FOLLOW_OFFSET_M` behind the track's recent heading. Followed tracks (of the broadcast
and of sessions with a connected client) are drawn thick and yellow; each following client
gets its own marker and the track's id at the head (client-scoped nodes). ``follow(None)``
stops.

**Follow sessions.** A console page is one operator's view: it makes up a session id and
gives viser's client (the 3D tab's iframe) the WebSocket URL
``ws://host:port/follow/<session>`` through viser's own ``?websocket=`` URL parameter. The
viser server accepts a WebSocket on any path; the scene reads the path of each client's
connection when it connects (:func:`session_of_path`), so every client of that page, and
any client it reconnects with, belongs to its session. ``follow(id, session=s)`` moves the
cameras of session ``s`` only; ``follow(id)`` without a session is the old broadcast: every
client follows ``id`` and the sessions' own choices are dropped. A session's ``None``
stops its clients only (it also shadows a broadcast choice). A client that connects while
its session (or the broadcast) follows a track starts at the track's head.

Everything is in the site frame (x east, y north, z up, m), which is viser's default
``+z`` up world. viser's frustums follow the OpenCV camera convention (x right, y down,
z forward), the same as ``R_world_cam``, so a frustum's orientation is ``R_world_cam``
as a quaternion.
"""

from __future__ import annotations

import collections
import contextlib
import io
import logging
import math
import re
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.site.folder import Site
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

__all__ = [
    "FOLLOW_OFFSET_M",
    "FOLLOW_PATH",
    "SESSION_PATTERN",
    "Scene3D",
    "follow_offset",
    "TerrainMesh",
    "display_host",
    "frustum_fov_aspect",
    "polyline_segments",
    "road_polylines",
    "session_of_path",
    "terrain_mesh",
    "texture_uv",
    "track_colour",
    "wxyz_from_matrix",
]

log = logging.getLogger("demtrack.server")

_PALETTE = np.array(
    [
        (230, 25, 75),
        (60, 180, 75),
        (0, 130, 200),
        (245, 130, 48),
        (145, 30, 180),
        (70, 240, 240),
        (240, 50, 230),
        (210, 245, 60),
        (0, 128, 128),
        (170, 110, 40),
    ],
    dtype=np.uint8,
)
_SENSOR_COLOURS = [(255, 215, 0), (0, 200, 255), (255, 105, 180), (160, 255, 120)]
_LIFT_M = 0.4  # draw lines this far above the terrain so the mesh does not swallow them
_MAX_TRACKS = 40
#: Segments per drawn piece of a track's polyline (see :meth:`Scene3D._draw_track`).
_PIECE_SEGMENTS = 256
_FOLLOW_COLOUR = (255, 230, 0)  # the console's selection colour
#: Where a camera starts when it begins to follow: this far behind the track (m,
#: horizontally) and this far above its newest point.
FOLLOW_OFFSET_M = (60.0, 35.0)
#: A follow session id (made up by a console page): URL-safe, 8 to 64 characters.
SESSION_PATTERN = r"^[A-Za-z0-9_-]{8,64}$"
#: The WebSocket path prefix a viser client joins a follow session with:
#: ``ws://host:port/follow/<session>``.
FOLLOW_PATH = "/follow/"
#: Most sessions whose follow choice is kept (the oldest choice goes first).
_MAX_SESSIONS = 256
#: How long (s) a client just aimed is aimed again until it reports looking at the target
#: (a camera report it sent before our move can land after it and undo it on our side).
_SETTLE_S = 20.0
_SESSION_RE = re.compile(SESSION_PATTERN)


def session_of_path(path: str | None) -> str | None:
    """The follow session a viser client's WebSocket request path names.

    Parameters
    ----------
    path : str or None
        The request target, e.g. ``/follow/abcd1234?x=1`` (the query is ignored).

    Returns
    -------
    str or None
        The session id, or None for any other path (``/``, a malformed id).
    """
    if not path:
        return None
    p = path.partition("?")[0]
    if not p.startswith(FOLLOW_PATH):
        return None
    sid = p[len(FOLLOW_PATH) :].rstrip("/")
    return sid if _SESSION_RE.match(sid) else None


def _websocket_path(server: Any, client_id: int) -> str | None:
    """The request path of a viser client's WebSocket (None if it cannot be read).

    viser 1.1 keeps each live ``websockets`` connection in its WebSocket server's
    ``_live_connections`` (from before its connect callbacks run until after its
    disconnect callbacks); this is the one private attribute the scene reads, and
    ``tests/server/test_scene3d.py`` fails if a viser upgrade moves it.
    """
    try:
        conn = server._websock_server._live_connections[client_id]
        return str(conn.request.path)
    except (AttributeError, KeyError, TypeError):
        return None


def wxyz_from_matrix(R: np.ndarray) -> np.ndarray:  # noqa: N803 - a rotation matrix is R
    """Unit quaternion ``(w, x, y, z)`` (``w >= 0``) of a proper rotation matrix.

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        Rotation (orthonormal, determinant +1), e.g. ``R_world_cam``.

    Returns
    -------
    ndarray, shape (4,)
    """
    m = np.asarray(R, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    # Shepperd: take the largest of the four candidates' squares for stability.
    cand = np.array([tr, m[0, 0], m[1, 1], m[2, 2]])
    k = int(np.argmax(cand))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    out /= np.linalg.norm(out)
    return -out if out[0] < 0 else out


def frustum_fov_aspect(intrinsics: Intrinsics) -> tuple[float, float]:
    """Viser's frustum ``(fov, aspect)``: vertical field of view (rad), width / height.

    From the undistorted image edges (the image spans ``u in [-0.5, width - 0.5]``,
    ``v in [-0.5, height - 0.5]``) through the principal point, so the frustum's edges
    are the rays of the image's edge midpoints when the principal point is centred and
    the distortion radial.
    """
    i = intrinsics
    xn, yn = i.undistort(
        np.array([-0.5, i.width - 0.5, i.cx, i.cx]), np.array([i.cy, i.cy, -0.5, i.height - 0.5])
    )
    tan_x = 0.5 * float(xn[1] - xn[0])
    tan_y = 0.5 * float(yn[3] - yn[2])
    return 2.0 * math.atan(tan_y), tan_x / tan_y


@dataclass(frozen=True)
class TerrainMesh:
    """A triangle mesh of the DEM surface.

    Attributes
    ----------
    vertices : ndarray, shape (n, 3)
        Site frame (m): decimated cell centres at their elevation.
    faces : ndarray, shape (m, 3)
        Vertex indices, counter-clockwise seen from above (normals up); no face
        touches a nodata cell.
    """

    vertices: np.ndarray
    faces: np.ndarray


def _take(n: int, step: int) -> np.ndarray:
    idx = np.arange(0, n, step)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def terrain_mesh(dem: Dem, max_side: int = 250) -> TerrainMesh:
    """The DEM's surface on at most ``max_side`` vertices per side.

    Vertices are cell centres (every ``step``-th row and column, always including the
    last), at the cell's elevation.
    """
    g = dem.grid
    step = max(1, math.ceil(max(g.nrows, g.ncols) / max_side))
    rows, cols = _take(g.nrows, step), _take(g.ncols, step)
    z = np.asarray(dem.elevation, dtype=np.float64)[np.ix_(rows, cols)]
    x = g.x_min + (cols + 0.5) * g.cell_m
    y = g.y_max - (rows + 0.5) * g.cell_m
    xx, yy = np.meshgrid(x, y)
    ok = np.isfinite(z)
    zf = np.where(ok, z, np.nanmin(z) if ok.any() else 0.0)
    vertices = np.column_stack([xx.ravel(), yy.ravel(), zf.ravel()])
    nr, nc = len(rows), len(cols)
    idx = np.arange(nr * nc).reshape(nr, nc)
    nw, ne, sw, se = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    okf = ok.ravel()
    tris = np.concatenate(
        [np.stack([nw, sw, se], -1).reshape(-1, 3), np.stack([nw, se, ne], -1).reshape(-1, 3)]
    )
    tris = tris[okf[tris].all(axis=1)]
    return TerrainMesh(vertices, tris.astype(np.int32))


def texture_uv(xy: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Texture coordinates of site-frame points on an image covering ``grid``.

    ``u`` runs west to east over the grid's outer edges and ``v`` south to north
    (0 at the bottom row's southern edge), the OBJ / trimesh convention.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Site frame east, north (m).
    grid : GridSpec
        The image's grid (row 0 north).

    Returns
    -------
    ndarray, shape (n, 2)
    """
    xy = np.asarray(xy, dtype=np.float64)
    u = (xy[:, 0] - grid.x_min) / (grid.ncols * grid.cell_m)
    v = (xy[:, 1] - grid.y_min) / (grid.nrows * grid.cell_m)
    return np.column_stack([u, v])


def road_polylines(site: Site, step_m: float = 2.0, lift_m: float = _LIFT_M) -> list[np.ndarray]:
    """Road centre lines draped on the DEM: one ``(k, 3)`` array (site frame, m) each."""
    if site.roads is None:
        return []
    out = []
    for line in site.roads.lines:
        n = max(2, int(math.ceil(line.length / step_m)) + 1)
        pts = np.array([line.interpolate(s).coords[0] for s in np.linspace(0, line.length, n)])
        z = site.dem.sample(pts[:, 0], pts[:, 1])
        keep = np.isfinite(z)
        if keep.sum() >= 2:
            out.append(np.column_stack([pts[keep, :2], z[keep] + lift_m]))
    return out


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """Consecutive point pairs of a polyline: shape ``(k - 1, 2, 3)``."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[:-1], p[1:]], axis=1)


def track_colour(track_id: int) -> tuple[int, int, int]:
    """A track's colour (RGB 0-255), fixed by its id."""
    c = _PALETTE[int(track_id) % len(_PALETTE)]
    return int(c[0]), int(c[1]), int(c[2])


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


def display_host(host: str) -> str:
    """The host to put in URLs for a bind address (a wildcard becomes 127.0.0.1)."""
    if host in ("", "0.0.0.0", "::", "[::]"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


@dataclass
class _Ray:
    det_id: int
    sensor: str
    origin: np.ndarray
    hits: np.ndarray  # (k, 3), road hit appended last when there is one
    chosen: int | None = None


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


@dataclass
class _Follow:
    """One follow choice: of a session, or the broadcast one (key None)."""

    track_id: int | None  # None: this session stopped (shadows a broadcast choice)
    target: np.ndarray | None = None  # look-at point last aimed at
    offset: np.ndarray | None = None  # where cameras that start following are put


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
        self._configure_gui()
        self.nodes: dict[str, Any] = {}
        self.n_messages = 0
        self.n_dropped = 0
        self.error: BaseException | None = None
        self._inbox: collections.deque[dict[str, Any]] = collections.deque()
        self._inbox_max = 20_000
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._rays: collections.deque[_Ray] = collections.deque(maxlen=max_rays)
        self._tracks: dict[int, _Track] = {}
        self._dirty_rays = False
        self._dirty_tracks: set[int] = set()
        #: Follow choices by session (None: the broadcast one); the scene thread's own.
        self._follows: dict[str | None, _Follow] = {}
        #: The latest choices asked for (the scene thread applies them on its next pass).
        self._asked: dict[str | None, int | None] = {}
        #: Each connected client's session (None: it joined none), set when it connects.
        self._client_session: dict[int, str | None] = {}
        #: Each following client's own head marker and label (client-scoped nodes).
        self._markers: dict[int, tuple[Any, Any]] = {}
        #: Clients aimed but not yet seen looking at the target: id -> (target, offset,
        #: monotonic deadline or None before the client's first report since the move;
        #: the move's time is in ``_aimed_at``). The scene thread's own.
        self._unsettled: dict[int, tuple[np.ndarray, np.ndarray, float | None]] = {}
        #: Wall-clock time of each client's latest move by us (kept once it settled).
        self._aimed_at: dict[int, float] = {}
        #: Every client's starting view (``initial_camera``: position, look-at), set with it.
        self._home: tuple[np.ndarray, np.ndarray] | None = None
        #: Tracks drawn as followed: the broadcast's and those of sessions with a client.
        self._highlighted: set[int] = set()
        self._aim_lock = threading.Lock()
        self.server.on_client_connect(self._on_client_connect)
        self.server.on_client_disconnect(self._on_client_disconnect)
        self._thread = threading.Thread(target=self._run, name="demtrack-scene3d", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- public
    def publish(self, messages: list[dict[str, Any]]) -> None:
        """Queue stream messages (any thread; never blocks). The oldest drop when full."""
        for m in messages:
            if m.get("type") in ("fix", "track_update"):
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
        if session is None:
            self._asked.clear()
        else:
            self._asked.pop(session, None)
            while len(self._asked) >= _MAX_SESSIONS:
                oldest = next((k for k in self._asked if k is not None), None)
                if oldest is None:
                    break
                del self._asked[oldest]
        self._asked[session] = tid
        self._inbox.append({"type": "_follow", "track_id": tid, "track": track, "session": session})
        self._wake.set()

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
        asked = dict(self._asked)
        track_id = asked[session] if session in asked else asked.get(None)
        rec = self._effective(session)
        target = None if rec is None or rec.track_id != track_id else rec.target
        clients = []
        for cid, client in sorted(self.server.get_clients().items()):
            mine = self._client_session.get(cid)
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

    # ----------------------------------------------------------------- static
    def _configure_gui(self) -> None:
        """Keep viser's control panel out of the view: small, no logo, minimised.

        The console embeds the scene in a tab about 640 px wide at 1280 x 800; viser's
        panel (scene tree, camera tools) stays one click away in its minimised bar.
        Theme and placement are persistent messages, so later clients get them too.
        """
        gui = self.server.gui
        gui.configure_theme(
            control_width="small", show_logo=False, show_share_button=False, dark_mode=True
        )
        gui.main_panel.minimize()

    def _add(self, name: str, handle: Any) -> Any:
        self.nodes[name] = handle
        return handle

    def _build_static(self) -> None:
        scene = self.server.scene
        site = self.site
        g = site.dem.grid
        lo, hi = site.dem.elevation_range()
        span = max(g.ncols, g.nrows) * g.cell_m
        cam = self.server.initial_camera
        cx, cy = 0.5 * (g.bounds[0] + g.bounds[2]), 0.5 * (g.bounds[1] + g.bounds[3])
        cam.position = (cx, cy - 0.65 * span, hi + 0.45 * span)
        cam.look_at = (cx, cy, lo)
        self._home = (np.asarray(cam.position, float), np.asarray(cam.look_at, float))
        cam.up = (0.0, 0.0, 1.0)
        cam.near = 0.5
        cam.far = 20.0 * span
        self._add_terrain()
        for k, sensor in enumerate(sorted(site.sensors.values(), key=lambda s: s.id)):
            self._add_camera(sensor, _SENSOR_COLOURS[k % len(_SENSOR_COLOURS)], span)
        roads = road_polylines(site)
        if roads:
            segs = np.concatenate([polyline_segments(p) for p in roads])
            self._add(
                "/roads",
                scene.add_line_segments(
                    "/roads", segs, (250, 250, 250), thickness=3.0, thickness_units="screen"
                ),
            )

    def _add_terrain(self) -> None:
        import trimesh
        from PIL import Image

        from demtrack.core.site.orthophoto import read_orthophoto

        mesh = terrain_mesh(self.site.dem, self.mesh_side)
        visual: Any = None
        if self.site.orthophoto_path is not None:
            rgb, grid = read_orthophoto(self.site.orthophoto_path)
            image = Image.fromarray(rgb)
            image.thumbnail((self.texture_px, self.texture_px))
            uv = texture_uv(mesh.vertices[:, :2], grid)
            material = trimesh.visual.material.SimpleMaterial(image=image, diffuse=(255,) * 4)
            visual = trimesh.visual.TextureVisuals(uv=uv, image=image, material=material)
        else:
            z = mesh.vertices[:, 2]
            t = (z - z.min()) / max(float(np.ptp(z)), 1e-9)
            colours = np.column_stack(
                [80 + 120 * t, 140 + 60 * t, 80 + 40 * t, np.full_like(t, 255)]
            )
            visual = trimesh.visual.ColorVisuals(vertex_colors=colours.astype(np.uint8))
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, visual=visual, process=False)
        self._add("/terrain", self.server.scene.add_mesh_trimesh("/terrain", tm))

    def _add_camera(self, sensor: Any, colour: tuple[int, int, int], span: float) -> None:
        scene = self.server.scene
        camera = sensor.camera
        fov, aspect = frustum_fov_aspect(camera.intrinsics)
        image = None
        if sensor.image_path is not None and sensor.image_path.is_file():
            from PIL import Image

            with Image.open(sensor.image_path) as raw:
                rgb = raw.convert("RGB")
                rgb.thumbnail((480, 480))
                image = np.asarray(rgb)
        name = f"/cameras/{sensor.id}"
        self._add(
            name,
            scene.add_camera_frustum(
                name,
                fov=fov,
                aspect=aspect,
                scale=0.05 * span,
                thickness=2.0,
                thickness_units="screen",
                color=colour,
                image=image,
                wxyz=wxyz_from_matrix(camera.R_world_cam),
                position=np.asarray(camera.position_enu, dtype=np.float64),
            ),
        )
        label = f"/labels/{sensor.id}"
        self._add(
            label,
            scene.add_label(
                label,
                f"{sensor.id} ({sensor.name})",
                position=np.asarray(camera.position_enu, dtype=np.float64) + [0.0, 0.0, 3.0],
            ),
        )

    # ------------------------------------------------------------------- live
    def _run(self) -> None:
        try:
            self._build_static()
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
                self._on_fix(m["fix"])
            elif kind == "track_update":
                self._on_track(m["track"])
            elif kind == "_follow":
                self._on_follow(m["track_id"], m.get("track"), m.get("session"))
            elif kind == "_client":
                self._on_client(m["client"])
            elif kind == "_client_left":
                self._restyle()
            elif kind == "_flush":
                flushes.append(m["event"])
            self.n_messages += 1
        return flushes

    def _on_fix(self, fix: dict[str, Any]) -> None:
        hits = [[h["e_m"], h["n_m"], h["u_m"]] for h in fix.get("hits") or []]
        road = fix.get("road_hit")
        if road is not None:
            hits.append([road["e_m"], road["n_m"], road["u_m"]])
        if not hits:
            return
        ray = _Ray(
            int(fix["detection_id"]),
            str(fix["sensor"]),
            np.asarray(fix["origin_enu"], dtype=np.float64),
            np.asarray(hits, dtype=np.float64),
        )
        self._rays.append(ray)
        self._dirty_rays = True

    def _on_track(self, body: dict[str, Any]) -> None:
        tid = int(body["id"])
        tr = self._tracks.get(tid)
        if tr is None:
            tr = self._tracks[tid] = _Track(tid, str(body["cls"]), bool(body["live"]))
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
        self._dirty_tracks.add(tid)
        # The tracker's choice among a ray's hits: the one nearest the point it made.
        by_det = {r.det_id: r for r in self._rays}
        for p in pts:
            for det in p.get("detection_ids", []):
                ray = by_det.get(int(det))
                if ray is not None:
                    q = np.array([p["e_m"], p["n_m"], p["u_m"]])
                    ray.chosen = int(np.argmin(np.linalg.norm(ray.hits - q, axis=1)))
                    self._dirty_rays = True

    def _effective(self, session: str | None) -> _Follow | None:
        """The follow choice a client of ``session`` obeys (its own, else the broadcast)."""
        rec = None if session is None else self._follows.get(session)
        return rec if rec is not None else self._follows.get(None)

    def _followed_ids(self) -> set[int]:
        """Every followed track (kept from pruning)."""
        return {f.track_id for f in list(self._follows.values()) if f.track_id is not None}

    def _restyle(self) -> None:
        """Highlight the tracks someone looks at: the broadcast's and connected sessions'.

        A session whose page is gone (or has not opened its 3D view) keeps its choice for
        clients that connect later but does not colour the scene for everyone else.
        """
        present = set(list(self._client_session.values()))
        now = {
            f.track_id
            for k, f in list(self._follows.items())
            if f.track_id is not None and (k is None or k in present)
        }
        self._dirty_tracks |= now ^ self._highlighted  # their colour and thickness change
        self._highlighted = now

    def _on_follow(
        self, track_id: int | None, body: dict[str, Any] | None, session: str | None
    ) -> None:
        if session is None:
            self._follows.clear()  # the broadcast: every client, sessions' choices go
            if track_id is not None:
                self._follows[None] = _Follow(track_id)
        else:
            self._follows.pop(session, None)
            # A session's stop is kept only while it has a broadcast choice to shadow.
            if track_id is not None or None in self._follows:
                self._follows[session] = _Follow(track_id)
            sessions = [k for k in self._follows if k is not None]
            for k in sessions[: max(0, len(sessions) - _MAX_SESSIONS)]:
                del self._follows[k]
        self._restyle()
        if track_id is not None:
            known = self._tracks.get(track_id)
            if body is not None and int(body["id"]) == track_id:
                n = len(body.get("points") or [])
                if known is None or n > len(known.points):
                    self._on_track({**body, "first_index": 0})
                    self._dirty_tracks.add(track_id)
        # Clients that follow nothing now lose their marker; cameras stay where they are.
        for cid in list(self._markers):
            rec = self._effective(self._client_session.get(cid))
            if rec is None or rec.track_id is None:
                self._drop_marker(cid)

    def _points_of(self, track_id: int | None) -> np.ndarray | None:
        tr = None if track_id is None else self._tracks.get(track_id)
        if tr is None or not tr.points:
            return None
        return np.asarray(tr.points, dtype=np.float64)

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
                self._unsettled[int(client.client_id)] = (target, offset, None)
                self._aimed_at[int(client.client_id)] = time.time()

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
            if reported <= self._aimed_at.get(cid, 0.0):
                continue  # no report since our move: the camera is still ours
            pending = self._unsettled.get(cid)
            if pending is not None and not np.allclose(pending[0], target):
                self._unsettled.pop(cid, None)
                pending = None
            if pending is None:
                if home and not looks:
                    self._aim([client], target, offset, keep_offset=False)
                continue
            deadline = pending[2] if pending[2] is not None else now + _SETTLE_S
            if looks or (now > deadline and not home):
                self._unsettled.pop(cid, None)
                continue
            self._aim([client], target, pending[1], keep_offset=False)  # records a new move
            self._unsettled[cid] = (*self._unsettled[cid][:2], deadline)  # the first's end

    def _at_home(self, cam: Any) -> bool:
        """Whether ``cam`` (a client's reported camera) is the starting view."""
        if self._home is None:
            return False
        pos, look = self._home
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
        self._markers[int(client.client_id)] = (head, label)

    def _drop_marker(self, client_id: int) -> None:
        handles = self._markers.pop(client_id, None)
        for h in handles or ():
            with contextlib.suppress(Exception):  # the client may have left
                h.remove()

    def _on_client_connect(self, client: Any) -> None:
        """Note a new client's session; the scene thread aims it on its next pass."""
        cid = int(client.client_id)
        self._client_session[cid] = session_of_path(_websocket_path(self.server, cid))
        self._inbox.append({"type": "_client", "client": client})
        self._wake.set()

    def _on_client_disconnect(self, client: Any) -> None:
        cid = int(client.client_id)
        self._client_session.pop(cid, None)
        self._markers.pop(cid, None)  # its nodes went with it
        self._inbox.append({"type": "_client_left"})
        self._wake.set()

    def _on_client(self, client: Any) -> None:
        """A client that connects while its session follows a track starts looking at it."""
        cid = int(client.client_id)
        if cid not in self._client_session:
            return  # gone already
        self._restyle()
        rec = self._effective(self._client_session.get(cid))
        if rec is None or rec.track_id is None or rec.target is None or rec.offset is None:
            return
        self._aim([client], rec.target, rec.offset, keep_offset=False)
        self._mark(client, rec.track_id, rec.target)

    def _update_follow(self) -> None:
        """Aim each follow choice's clients at its track's newest point, if it moved."""
        if not self._follows:
            return
        groups: dict[str | None, list[Any]] = {}
        present = self.server.get_clients()
        for cid, client in present.items():
            session = self._client_session.get(cid)
            key = session if session is not None and session in self._follows else None
            groups.setdefault(key, []).append(client)
        for cid in [c for c in self._unsettled if c not in present]:
            del self._unsettled[cid]  # gone
        for cid in [c for c in self._aimed_at if c not in present]:
            del self._aimed_at[cid]
        for key, rec in list(self._follows.items()):
            pts = self._points_of(rec.track_id)
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

    def _render(self) -> None:
        scene = self.server.scene
        if self._dirty_rays and self._rays:
            self._dirty_rays = False
            sensors = sorted(self.site.sensors)
            segs, colours, all_hits, chosen = [], [], [], []
            for r in self._rays:
                far = r.hits[np.argmax(np.linalg.norm(r.hits - r.origin, axis=1))]
                segs.append([r.origin, far])
                k = sensors.index(r.sensor) if r.sensor in sensors else 0
                colours.append([_SENSOR_COLOURS[k % len(_SENSOR_COLOURS)]] * 2)
                all_hits.append(r.hits)
                if r.chosen is not None:
                    chosen.append(r.hits[r.chosen])
            self._add(
                "/rays/lines",
                scene.add_line_segments(
                    "/rays/lines",
                    np.asarray(segs),
                    np.asarray(colours, dtype=np.uint8),
                    thickness=1.5,
                    thickness_units="screen",
                ),
            )
            self._add(
                "/rays/hits",
                scene.add_point_cloud(
                    "/rays/hits",
                    np.concatenate(all_hits).astype(np.float32),
                    (255, 255, 255),
                    point_size=1.5,
                    point_shape="circle",
                    precision="float32",
                ),
            )
            pts = np.asarray(chosen, dtype=np.float32).reshape(-1, 3)
            self._add(
                "/rays/chosen",
                scene.add_point_cloud(
                    "/rays/chosen",
                    pts,
                    (255, 30, 30),
                    point_size=3.0,
                    point_shape="circle",
                    precision="float32",
                ),
            )
        if self._dirty_tracks:
            self._prune_tracks()
            for tid in sorted(self._dirty_tracks):
                tr = self._tracks.get(tid)
                if tr is not None:
                    self._draw_track(tr)
            self._dirty_tracks.clear()
        self._update_follow()

    def _track_style(self, tr: _Track) -> tuple[tuple[int, int, int], float]:
        colour = track_colour(tr.id)
        if tr.id in self._highlighted:
            return _FOLLOW_COLOUR, 7.0
        if tr.live:
            return colour, 4.0
        c_r, c_g, c_b = (int(0.5 * c + 64) for c in colour)
        return (c_r, c_g, c_b), 2.0

    def _draw_track(self, tr: _Track) -> None:
        """Redraw the pieces of ``tr``'s polyline its new points touched.

        The polyline is drawn in pieces of :data:`_PIECE_SEGMENTS` segments
        (``/tracks/{id}/{k}``): a live track changes at its end (new points, a smoothed
        tail), so an update re-sends one or two pieces rather than the whole history.
        A new colour or thickness (followed, ended) redraws every piece.
        """
        n = len(tr.points)
        n_pieces = 0 if n < 2 else (n - 2) // _PIECE_SEGMENTS + 1
        style = self._track_style(tr)
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
            self._add(
                name,
                self.server.scene.add_line_segments(
                    name,
                    polyline_segments(p),
                    colour,
                    thickness=thickness,
                    thickness_units="screen",
                ),
            )
        tr.n_drawn, tr.style, tr.changed_from = n_pieces, style, n

    def _prune_tracks(self) -> None:
        if len(self._tracks) <= _MAX_TRACKS:
            return
        followed = self._followed_ids()
        ended = sorted(
            (t for t in self._tracks.values() if not t.live and t.id not in followed),
            key=lambda t: t.t_last,
        )
        for tr in ended[: len(self._tracks) - _MAX_TRACKS]:
            del self._tracks[tr.id]
            self._dirty_tracks.discard(tr.id)
            for k in range(tr.n_drawn):
                handle = self.nodes.pop(f"/tracks/{tr.id}/{k}", None)
                if handle is not None:
                    handle.remove()
