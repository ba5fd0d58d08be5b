"""The viser 3D scene: geometry helpers against independent references, and a live scene."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from demtrack.core.site.folder import load_site
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.server.messages import FixMessage, TrackUpdateMessage
from demtrack.server.scene3d import (
    Scene3D,
    class_colour,
    display_host,
    follow_offset,
    frustum_fov_aspect,
    polyline_segments,
    road_polylines,
    session_of_path,
    terrain_mesh,
    texture_uv,
    wxyz_from_matrix,
)
from demtrack.server.scene3d import following as scene_following
from demtrack.server.scene3d import tracks as scene_tracks

pytestmark = pytest.mark.timeout(180)


def matrix_of(wxyz) -> np.ndarray:
    """Rotation matrix of a viser quaternion, by scipy (which orders x, y, z, w)."""
    w, x, y, z = (float(a) for a in wxyz)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_quaternion_matches_scipy(seed):
    R = Rotation.random(random_state=np.random.default_rng(seed)).as_matrix()
    q = wxyz_from_matrix(R)
    assert q[0] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
    np.testing.assert_allclose(matrix_of(q), R, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, np.pi, -np.pi / 2, np.pi - 1e-9])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)])
def test_quaternion_near_half_turns(angle, axis):
    R = Rotation.from_rotvec(angle * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
    np.testing.assert_allclose(matrix_of(wxyz_from_matrix(R)), R, atol=1e-12)


@pytest.fixture(scope="module")
def site(sample_site_dir: Path):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def scene(site):
    # The session gate has its own tests below; these clients connect on any path.
    sc = Scene3D(site, host="127.0.0.1", port=0, max_rays=5, require_session=False)
    assert sc.wait_ready(120) and sc.error is None
    yield sc
    sc.stop()


@pytest.fixture(autouse=True)
def _clients_of_earlier_tests_gone(request):
    """A test on the shared scene starts once the viser clients of the tests before it have
    left: the server lists a closed client a moment longer, and a test that waits for "one
    client" could otherwise take that one for its own (CI once saw exactly this)."""
    if "scene" in request.fixturenames:
        sc = request.getfixturevalue("scene")
        wait_for(lambda: not sc.server.get_clients())


def test_static_scene_has_terrain_cameras_and_roads(scene, site):
    names = set(scene.nodes)
    assert {"/terrain", "/roads"} <= names
    assert {f"/cameras/{s}" for s in site.sensors} <= names
    assert scene.url == f"http://127.0.0.1:{scene.server.get_port()}/"


def test_frustum_looks_along_the_optical_axis(scene, site):
    """viser draws a frustum along its local +z, x right, y down (OpenCV, like our cameras).

    The pose is checked against rays the camera model itself back-projects: the
    principal point's ray is the frustum's +z, moving right in the image turns the ray
    towards +x, moving down towards +y.
    """
    for sid, sensor in site.sensors.items():
        cam = sensor.camera
        handle = scene.nodes[f"/cameras/{sid}"]
        R = matrix_of(handle.wxyz)
        np.testing.assert_allclose(handle.position, cam.position_enu, atol=1e-4)
        intr = cam.intrinsics
        _, d = cam.pixel_to_ray(
            [intr.cx, intr.cx + 1.0, intr.cx], [intr.cy, intr.cy, intr.cy + 1.0]
        )
        np.testing.assert_allclose(R @ [0, 0, 1], d[0], atol=1e-6)
        right = d[1] - d[0]
        down = d[2] - d[0]
        assert np.dot(R @ [1, 0, 0], right / np.linalg.norm(right)) > 0.999
        assert np.dot(R @ [0, 1, 0], down / np.linalg.norm(down)) > 0.999


def test_frustum_edges_are_the_image_edges(site):
    """The frustum's edge midpoints project to the image's edge midpoints (distortion in)."""
    for sensor in site.sensors.values():
        cam = sensor.camera
        intr = cam.intrinsics
        assert intr.has_distortion  # the sample cameras have radial distortion
        fov, aspect = frustum_fov_aspect(intr)
        ty = np.tan(fov / 2)
        p_cam = np.array([[0, -ty, 1], [0, ty, 1], [-ty * aspect, 0, 1], [ty * aspect, 0, 1]])
        u, v, front = cam.project(cam.position_enu + 50.0 * p_cam @ cam.R_world_cam.T)
        assert front.all()
        w, h = intr.width, intr.height
        np.testing.assert_allclose(v[:2], [-0.5, h - 0.5], atol=1e-6)
        np.testing.assert_allclose(u[2:], [-0.5, w - 0.5], atol=1e-6)
        np.testing.assert_allclose(u[:2], intr.cx, atol=1e-6)


def test_terrain_mesh_on_cell_centres_normals_up_and_no_holes():
    rng = np.random.default_rng(0)
    elev = rng.uniform(0, 5, (9, 7)).astype(np.float32)
    elev[3, 3] = np.nan  # the vertex of decimated row 1, column 1
    dem = Dem(GridSpec(100.0, 50.0, 2.0, 9, 7), elev)
    mesh = terrain_mesh(dem, max_side=4)  # step 3: rows 0 3 6 8, cols 0 3 6
    assert len(mesh.vertices) == 4 * 3
    xy = mesh.vertices[:, :2]
    assert set(np.round(xy[:, 0], 6)) == {101.0, 107.0, 113.0}
    assert set(np.round(xy[:, 1], 6)) == {49.0, 43.0, 37.0, 33.0}
    z = dem.sample(xy[:, 0], xy[:, 1])  # at a cell centre the surface is the cell's value
    kept = np.isfinite(z)
    np.testing.assert_allclose(mesh.vertices[kept, 2], z[kept], atol=1e-5)
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    assert (normals[:, 2] > 0).all()
    assert len(mesh.faces) == 12 - 6  # the NaN vertex is in 6 of the 12 triangles
    assert not np.isin(mesh.faces, np.flatnonzero(~kept)).any()


def test_texture_uv_spans_the_orthophoto_edges():
    g = GridSpec(-10.0, 20.0, 0.5, 40, 60)  # x -10..20, y 0..20
    uv = texture_uv(np.array([[-10.0, 0.0], [20.0, 20.0], [5.0, 10.0], [-9.75, 19.75]]), g)
    np.testing.assert_allclose(uv[:3], [[0, 0], [1, 1], [0.5, 0.5]])
    # The NW pixel's centre: half a pixel in from the west and north edges.
    np.testing.assert_allclose(uv[3], [0.5 / 60, 1 - 0.5 / 40])


def test_roads_lie_on_the_dem(site):
    lines = road_polylines(site, lift_m=0.0)
    assert len(lines) == len(site.roads.lines)
    for p in lines:
        np.testing.assert_allclose(p[:, 2], site.dem.sample(p[:, 0], p[:, 1]))
    seg = polyline_segments(lines[0])
    assert seg.shape == (len(lines[0]) - 1, 2, 3)
    np.testing.assert_array_equal(seg[1:, 0], seg[:-1, 1])


def test_display_host():
    assert display_host("0.0.0.0") == "127.0.0.1"
    assert display_host("::1") == "[::1]"
    assert display_host("example.org") == "example.org"


def hit(e, n, u):
    return {"e_m": e, "n_m": n, "u_m": u, "lat_deg": 40.0, "lon_deg": -79.0, "h_m": 300.0,
            "sigma_m": 0.5}  # fmt: skip


def fix_message(seq: int, det_id: int, hits: list[dict]) -> dict:
    msg = {
        "type": "fix",
        "seq": seq,
        "fix": {
            "detection_id": det_id,
            "t_s": float(det_id),
            "sensor": "cam1",
            "cls": "vehicle",
            "score": 0.9,
            "bbox": [1.0, 2.0, 3.0, 4.0],
            "foot_pixel": [2.0, 4.0],
            "origin_enu": [0.0, 0.0, 30.0],
            "direction_enu": [0.6, 0.0, -0.8],
            "hits": hits,
            "road_hit": None,
            "tracked": True,
        },
    }
    return FixMessage.model_validate(msg).model_dump()


def track_message(seq: int, points: list[tuple[float, float, float, int]]) -> dict:
    pts = [
        {
            "t_s": float(d),
            "e_m": e,
            "n_m": n,
            "u_m": u,
            "lat_deg": 40.0,
            "lon_deg": -79.0,
            "h_m": 300.0,
            "sensors": ["cam1"],
            "detection_ids": [d],
        }  # fmt: skip
        for e, n, u, d in points
    ]
    body = {"id": 7, "cls": "vehicle", "sensors": ["cam1"], "gaps": [], "live": True,
            "n_points": len(pts), "first_index": 0, "points": pts}  # fmt: skip
    return TrackUpdateMessage.model_validate(
        {"type": "track_update", "seq": seq, "track": body}
    ).model_dump()


def track_segments(scene, tid):
    """A track's drawn segments, its pieces (``/tracks/{tid}/{k}``) in order."""
    pieces = sorted(
        (int(name.rsplit("/", 1)[1]), np.asarray(node.points))
        for name, node in scene.nodes.items()
        if name.startswith(f"/tracks/{tid}/")
    )
    assert [k for k, _ in pieces] == list(range(len(pieces)))
    return np.concatenate([p for _, p in pieces]) if pieces else np.zeros((0, 2, 3))


def test_long_track_is_drawn_in_pieces_and_updates_redraw_only_its_end(scene, monkeypatch):
    """A long track's polyline is the same drawn in pieces; an update at the end
    re-sends only the piece(s) its changed points touch; a restyle re-sends every one."""
    from demtrack.server.scene3d import geometry as s3

    monkeypatch.setattr(scene_tracks, "_PIECE_SEGMENTS", 4)
    walk = [(float(k), 0.5 * k, 1.0 + 0.01 * k, 1000 + k) for k in range(11)]
    scene.publish([track_message(1, walk)])
    assert scene.flush()
    want = s3.polyline_segments(np.array([w[:3] for w in walk]) + [0, 0, s3._LIFT_M])
    tid = 7
    np.testing.assert_allclose(track_segments(scene, tid), want)
    assert len([n for n in scene.nodes if n.startswith(f"/tracks/{tid}/")]) == 3  # 4 + 4 + 2
    before = {n: h for n, h in scene.nodes.items() if n.startswith(f"/tracks/{tid}/")}
    # revise the last two points and add one: only piece 2 (segments 8..) changes
    more = [(20.0, 9.0, 1.5, 2000), (21.0, 9.5, 1.5, 2001), (22.0, 10.0, 1.5, 2002)]
    upd = track_message(2, more)
    upd["track"]["first_index"] = 9
    scene.publish([upd])
    assert scene.flush()
    pts = [w[:3] for w in walk[:9]] + [m[:3] for m in more]
    want = s3.polyline_segments(np.array(pts) + [0, 0, s3._LIFT_M])
    np.testing.assert_allclose(track_segments(scene, tid), want)
    after = {n: h for n, h in scene.nodes.items() if n.startswith(f"/tracks/{tid}/")}
    assert after[f"/tracks/{tid}/0"] is before[f"/tracks/{tid}/0"]
    assert after[f"/tracks/{tid}/1"] is before[f"/tracks/{tid}/1"]
    assert after[f"/tracks/{tid}/2"] is not before[f"/tracks/{tid}/2"]
    # a change inside piece 1 (point 6) redraws pieces 1 and 2 (segment 5 is in piece 1)
    upd = track_message(3, [(6.0, 7.0, 1.0, 3000)] + [w for w in walk[7:9]] + more)
    upd["track"]["first_index"] = 6
    scene.publish([upd])
    assert scene.flush()
    again = {n: h for n, h in scene.nodes.items() if n.startswith(f"/tracks/{tid}/")}
    assert again[f"/tracks/{tid}/0"] is before[f"/tracks/{tid}/0"]
    assert again[f"/tracks/{tid}/1"] is not before[f"/tracks/{tid}/1"]
    # the track ends: every piece gets the ended style
    end = track_message(4, [])
    end["track"]["live"] = False
    end["track"]["first_index"] = 12
    scene.publish([end])
    assert scene.flush()
    pieces = [h for n, h in scene.nodes.items() if n.startswith(f"/tracks/{tid}/")]
    assert len(pieces) == 3 and all(h.thickness == 2.0 for h in pieces)


def test_live_rays_hits_and_tracks(scene):
    # Two rays, each meeting the terrain twice; the track passes by the second hit of the
    # first ray and the first hit of the second: those are the tracker's choices.
    scene.publish(
        [
            fix_message(1, 101, [hit(10.0, 0.0, 16.0), hit(20.0, 0.0, 3.0)]),
            fix_message(2, 102, [hit(11.0, 1.0, 15.0), hit(21.0, 1.0, 2.0)]),
        ]
    )
    scene.publish([track_message(3, [(19.8, 0.1, 3.0, 101), (11.2, 1.0, 15.0, 102)])])
    assert scene.flush()
    assert {"/rays/lines", "/rays/hits", "/rays/chosen", "/tracks/7/0"} <= set(scene.nodes)
    chosen = np.asarray(scene.nodes["/rays/chosen"].points)
    np.testing.assert_allclose(chosen, [[20.0, 0.0, 3.0], [11.0, 1.0, 15.0]])
    assert len(scene.nodes["/rays/hits"].points) == 4
    lines = np.asarray(scene.nodes["/rays/lines"].points)
    np.testing.assert_allclose(lines[0], [[0.0, 0.0, 30.0], [20.0, 0.0, 3.0]])  # to the far hit
    track = track_segments(scene, 7)
    assert track.shape == (1, 2, 3)
    # Only the newest max_rays (5) rays are kept.
    scene.publish([fix_message(10 + k, 200 + k, [hit(k, 0.0, 1.0)]) for k in range(8)])
    assert scene.flush()
    assert len(scene.nodes["/rays/hits"].points) == 5
    # A revised tail (first_index) replaces the points from there on.
    upd = track_message(30, [(5.0, 5.0, 1.0, 300), (6.0, 5.0, 1.0, 301)])
    upd["track"]["first_index"] = 1
    scene.publish([upd])
    assert scene.flush()
    track = track_segments(scene, 7)
    np.testing.assert_allclose(
        track[:, :, :2].reshape(-1, 2)[[0, 1, 3]], [[19.8, 0.1], [5, 5], [6, 5]]
    )


def test_stop_closes_the_port(site):
    sc = Scene3D(site, host="127.0.0.1", port=0)
    assert sc.wait_ready(120)
    port = sc.server.get_port()
    with socket.create_connection(("127.0.0.1", port), timeout=5):
        pass
    sc.stop()
    with pytest.raises(OSError), socket.create_connection(("127.0.0.1", port), timeout=5):
        pass


# ------------------------------------------------------------------------- following
class FakeViserClient:
    """A viser client without a browser: it reports a camera and reads what it is sent.

    It speaks viser's own wire protocol (a msgpack ``ViewerCameraMessage`` over the
    WebSocket, with the ``viser-v<version>`` subprotocol), so the server sees a real
    client: :meth:`viser.ViserServer.get_clients` lists it once its camera arrived.
    """

    def __init__(self, port: int, path: str = "/") -> None:
        import threading

        import viser
        from websockets.sync.client import connect

        self.ws = connect(
            f"ws://127.0.0.1:{port}{path}",
            subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
            max_size=None,
        )
        self.n_received = 0
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self) -> None:
        try:
            while True:
                self.ws.recv()
                self.n_received += 1
        except Exception:  # noqa: BLE001 - closed
            return

    def send_camera(self, position, look_at) -> None:
        import msgspec

        self.ws.send(
            msgspec.msgpack.encode(
                {
                    "type": "ViewerCameraMessage",
                    "wxyz": [1.0, 0.0, 0.0, 0.0],
                    "position": [float(x) for x in position],
                    "fov": 1.0,
                    "near": 0.1,
                    "far": 5000.0,
                    "image_height": 600,
                    "image_width": 800,
                    "look_at": [float(x) for x in look_at],
                    "up_direction": [0.0, 0.0, 1.0],
                }
            )
        )

    def close(self) -> None:
        self.ws.close()


def wait_for(cond, timeout_s: float = 10.0) -> None:
    import time

    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_follow_offset_is_behind_the_heading_and_above():
    # Moving east: the camera is due west of the head, up_m above it.
    pts = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [10.0, 0.0, 5.0], [10.5, 0.0, 5.0]])
    np.testing.assert_allclose(follow_offset(pts, 60.0, 35.0), [-60.0, 0.0, 35.0])
    # Heading from the newest point back to the last one at least 2 m away (north-east).
    pts = np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 0.0], [3.5, 3.5, 0.0]])
    np.testing.assert_allclose(follow_offset(pts, 10.0, 1.0), [-10 / np.sqrt(2)] * 2 + [1.0])
    # A track that has not moved 2 m is looked at from the south.
    np.testing.assert_allclose(follow_offset(np.zeros((3, 3)), 60.0, 35.0), [0.0, -60.0, 35.0])


def follow_body(track_id: int, points: list[tuple[float, float, float]]) -> dict:
    pts = [
        {
            "t_s": float(k),
            "e_m": e,
            "n_m": n,
            "u_m": u,
            "lat_deg": 40.0,
            "lon_deg": -79.0,
            "h_m": 300.0,
            "sensors": ["cam1"],
            "detection_ids": [1000 + k],
        }  # fmt: skip
        for k, (e, n, u) in enumerate(points)
    ]
    return {"id": track_id, "cls": "human", "sensors": ["cam1"], "gaps": [], "live": True,
            "n_points": len(pts), "first_index": 0, "points": pts}  # fmt: skip


def test_follow_moves_every_client_camera_to_the_track(scene):
    lift = np.array([0.0, 0.0, 0.4])
    a = FakeViserClient(scene.server.get_port())
    try:
        a.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
        wait_for(lambda: len(scene.server.get_clients()) == 1)
        # Following a track the scene has never been sent: its body comes with the call.
        walk = [(20.0 + 4.0 * k, -10.0, 3.0) for k in range(6)]  # eastwards
        scene.follow(41, follow_body(41, walk))
        assert scene.flush()
        head = np.array(walk[-1]) + lift
        [client] = scene.server.get_clients().values()
        np.testing.assert_allclose(client.camera.look_at, head, atol=1e-9)
        np.testing.assert_allclose(client.camera.position - head, follow_offset(np.array(walk)))
        state = scene.follow_state()
        assert state["track_id"] == 41
        np.testing.assert_allclose(state["look_at_enu"], head)
        np.testing.assert_allclose(state["clients"][0]["look_at_enu"], head)
        # The followed polyline is highlighted; a marker sits at its head.
        line = scene.nodes["/tracks/41/0"]
        assert np.asarray(line.colors).reshape(-1, 3)[0].tolist() == [255, 230, 0]
        assert line.thickness == 7.0
        [(marker, label)] = scene._markers.values()  # the client's own, client-scoped
        np.testing.assert_allclose(marker.position, head)
        assert label.text == "#41"
        # The operator orbits (a new camera from the client); new fixes arrive: the camera
        # follows the new head and keeps the operator's offset.
        mine = np.array([15.0, 25.0, 40.0])
        a.send_camera(position=head + mine, look_at=head)
        wait_for(lambda: np.allclose(client.camera.position, head + mine))
        more = [(44.0 + 4.0 * k, -10.0 + 2.0 * k, 2.0) for k in range(1, 4)]
        upd = follow_body(41, walk + more)
        upd["points"] = upd["points"][len(walk) :]
        upd["first_index"] = len(walk)
        scene.publish([TrackUpdateMessage.model_validate(
            {"type": "track_update", "seq": 1, "track": upd}).model_dump()])  # fmt: skip
        assert scene.flush()
        head2 = np.array(more[-1]) + lift
        np.testing.assert_allclose(client.camera.look_at, head2, atol=1e-9)
        np.testing.assert_allclose(client.camera.position, head2 + mine, atol=1e-9)
        # A client that connects while following starts by looking at the head.
        b = FakeViserClient(scene.server.get_port())
        try:
            b.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
            wait_for(lambda: len(scene.server.get_clients()) == 2)
            newer = max(scene.server.get_clients().items())[1]
            wait_for(lambda: np.allclose(newer.camera.look_at, head2))
        finally:
            b.close()
        # Stopping: the head marker goes, the polyline gets its class's colour back, and the
        # cameras stay where they are.
        scene.follow(None)
        assert scene.flush()
        assert not scene._markers and scene.follow_state()["track_id"] is None
        line = scene.nodes["/tracks/41/0"]
        assert tuple(np.asarray(line.colors).reshape(-1, 3)[0]) == class_colour(
            scene._tracks.tracks[41].cls
        )
        assert line.thickness == 4.0
        np.testing.assert_allclose(client.camera.look_at, head2, atol=1e-9)
    finally:
        a.close()
        scene.follow(None)


def test_a_stale_camera_report_after_a_move_is_aimed_again_until_the_client_looks(scene):
    """A client's report sent before our move reached it lands after the move: aim again.

    Once a report of the client looks at the target, the operator's own moves are kept.
    """
    lift = np.array([0.0, 0.0, 0.4])
    session = "settle-0123456"
    a = FakeViserClient(scene.server.get_port(), f"/follow/{session}")
    try:
        stale = (np.array([0.0, -200.0, 150.0]), np.zeros(3))
        a.send_camera(*stale)
        wait_for(lambda: len(scene.follow_state(session)["clients"]) == 1)
        [client] = (c for c in scene.server.get_clients().values()
                    if scene._client_session.get(int(c.client_id)) == session)  # fmt: skip
        walk = [(30.0, 10.0 + 4.0 * k, 2.0) for k in range(5)]  # northwards
        head = np.array(walk[-1]) + lift
        scene.follow(61, follow_body(61, walk), session=session)
        assert scene.flush()
        start = client.camera.position.copy()
        np.testing.assert_allclose(client.camera.look_at, head, atol=1e-9)
        # The client's older camera arrives after the move: the scene aims it again.
        a.send_camera(*stale)
        wait_for(lambda: np.allclose(client.camera.look_at, head, atol=1e-9))
        np.testing.assert_allclose(client.camera.position, start, atol=1e-9)
        # The client reports the target: settled. The operator then pans: kept.
        a.send_camera(start, head)
        wait_for(lambda: client.camera.update_timestamp > 0 and scene._unsettled.get(
            int(client.client_id)) is None)  # fmt: skip
        pan = (start + [5.0, 0.0, 0.0], head + [5.0, 0.0, 0.0])
        a.send_camera(*pan)
        wait_for(lambda: np.allclose(client.camera.look_at, pan[1]))
        assert scene.flush() and scene.flush()  # passes after the report
        np.testing.assert_allclose(client.camera.look_at, pan[1])
        np.testing.assert_allclose(client.camera.position, pan[0])
    finally:
        a.close()
        scene.follow(None, session=session)


def test_a_client_back_at_the_starting_view_is_aimed_again(scene, monkeypatch):
    """A viewer that starts afresh (the starting view) long after its aim is aimed again.

    A slow page's viser client can reset its camera to the server's initial view after it
    settled on the followed track, or after the settling time; an operator's pan is kept.
    """
    monkeypatch.setattr(scene_following, "_SETTLE_S", 0.3)
    lift = np.array([0.0, 0.0, 0.4])
    session = "home-0123456789"
    walk = [(-20.0, 10.0 + 4.0 * k, 2.0) for k in range(5)]
    head = np.array(walk[-1]) + lift
    cam0 = scene.server.initial_camera
    home = (np.asarray(cam0.position, float), np.asarray(cam0.look_at, float))
    a = FakeViserClient(scene.server.get_port(), f"/follow/{session}")
    try:
        a.send_camera(*home)  # a viewer's first report: the starting view
        wait_for(lambda: len(scene.follow_state(session)["clients"]) == 1)
        [client] = (c for c in scene.server.get_clients().values()
                    if scene._client_session.get(int(c.client_id)) == session)  # fmt: skip
        scene.follow(62, follow_body(62, walk), session=session)
        assert scene.flush()
        np.testing.assert_allclose(client.camera.look_at, head, atol=1e-9)
        start = client.camera.position.copy()
        a.send_camera(start, head)  # it looks: settled
        wait_for(lambda: scene._unsettled.get(int(client.client_id)) is None)
        time.sleep(0.6)  # past the settling time
        before = client.camera.update_timestamp
        a.send_camera(*home)  # the viewer started afresh
        wait_for(lambda: client.camera.update_timestamp > before)  # received
        wait_for(lambda: np.allclose(client.camera.look_at, head, atol=1e-9))
        np.testing.assert_allclose(client.camera.position, start, atol=1e-9)
        # An operator's pan after that is kept.
        a.send_camera(start, head)
        wait_for(lambda: scene._unsettled.get(int(client.client_id)) is None)
        time.sleep(0.6)
        pan = (start + [5.0, 0.0, 0.0], head + [5.0, 0.0, 0.0])
        a.send_camera(*pan)
        wait_for(lambda: np.allclose(client.camera.look_at, pan[1]))
        assert scene.flush() and scene.flush()
        np.testing.assert_allclose(client.camera.look_at, pan[1])
    finally:
        a.close()
        scene.follow(None, session=session)


def test_session_of_path():
    assert session_of_path("/follow/abcd1234") == "abcd1234"
    assert session_of_path("/follow/abcd-_1234/?x=1") == "abcd-_1234"
    sid = "f" * 64
    assert session_of_path(f"/follow/{sid}") == sid
    for bad in (None, "", "/", "/follow/", "/follow/short", "/follow/" + "f" * 65,
                "/follow/abcd1234/x", "/follow/abc%2E1234", "/x/follow/abcd1234",
                "/Follow/abcd1234", "/follow/abcd 1234"):  # fmt: skip
        assert session_of_path(bad) is None, bad


def test_follow_sessions_move_only_their_own_clients(scene):
    """Two operators' pages (sessions A, B) and a plain client: each follows its own."""
    lift = np.array([0.0, 0.0, 0.4])
    port = scene.server.get_port()
    home = (np.array([0.0, -200.0, 150.0]), np.zeros(3))
    sa, sb = "sessionA-0123", "sessionB-4567"
    walks = {
        51: [(20.0 + 4.0 * k, -10.0, 3.0) for k in range(6)],  # eastwards
        52: [(-30.0, 10.0 + 5.0 * k, 6.0) for k in range(5)],  # northwards
        53: [(5.0, 5.0 - 3.0 * k, 1.0) for k in range(4)],  # southwards
        54: [(-5.0 - 3.0 * k, -40.0, 2.0) for k in range(4)],  # westwards
    }
    heads = {t: np.array(w[-1]) + lift for t, w in walks.items()}

    def handle(fake_count: int):
        wait_for(lambda: len(scene.server.get_clients()) == fake_count)
        return max(scene.server.get_clients().items())[1]

    def at_home(client) -> bool:
        return np.allclose(client.camera.position, home[0]) and np.allclose(
            client.camera.look_at, home[1]
        )

    def looks_at(client, tid) -> bool:
        return np.allclose(client.camera.look_at, heads[tid], atol=1e-9)

    fakes = []
    try:
        a = FakeViserClient(port, f"/follow/{sa}")
        fakes.append(a)
        a.send_camera(*home)
        ca = handle(1)
        b = FakeViserClient(port, f"/follow/{sb}")
        fakes.append(b)
        b.send_camera(*home)
        cb = handle(2)
        plain = FakeViserClient(port)
        fakes.append(plain)
        plain.send_camera(*home)
        cp = handle(3)
        # Each client's session comes from its WebSocket path (read when it connects).
        wait_for(lambda: len(scene.follow_state()["clients"]) == 3)
        sessions = {k["id"]: k["session"] for k in scene.follow_state()["clients"]}
        assert sessions == {ca.client_id: sa, cb.client_id: sb, cp.client_id: None}

        scene.follow(51, follow_body(51, walks[51]), session=sa)
        assert scene.flush()
        assert looks_at(ca, 51)
        np.testing.assert_allclose(
            ca.camera.position - heads[51], follow_offset(np.array(walks[51]))
        )
        assert at_home(cb) and at_home(cp)
        scene.follow(52, follow_body(52, walks[52]), session=sb)
        assert scene.flush()
        assert looks_at(cb, 52) and looks_at(ca, 51) and at_home(cp)
        # Each following client has its own marker at its own track's head.
        marks = {cid: (m.position, lab.text) for cid, (m, lab) in scene._markers.items()}
        assert set(marks) == {ca.client_id, cb.client_id}
        np.testing.assert_allclose(marks[ca.client_id][0], heads[51])
        np.testing.assert_allclose(marks[cb.client_id][0], heads[52])
        assert (marks[ca.client_id][1], marks[cb.client_id][1]) == ("#51", "#52")
        # Both followed tracks are highlighted.
        for tid in (51, 52):
            assert scene.nodes[f"/tracks/{tid}/0"].thickness == 7.0
        # A session's state: its choice and its clients; without one: the broadcast.
        st = scene.follow_state(sa)
        assert st["track_id"] == 51 and [k["id"] for k in st["clients"]] == [ca.client_id]
        np.testing.assert_allclose(st["look_at_enu"], heads[51])
        st = scene.follow_state()
        assert st["track_id"] is None and st["look_at_enu"] is None
        assert {k["id"]: k["track_id"] for k in st["clients"]} == {
            ca.client_id: 51, cb.client_id: 52, cp.client_id: None}  # fmt: skip
        assert scene.follow_state("sessionC-none")["clients"] == []

        # A late client of session A starts at A's track; a late plain one stays put.
        a2 = FakeViserClient(port, f"/follow/{sa}")
        fakes.append(a2)
        a2.send_camera(*home)
        ca2 = handle(4)
        wait_for(lambda: looks_at(ca2, 51))
        late = FakeViserClient(port)
        fakes.append(late)
        late.send_camera(*home)
        cl = handle(5)
        wait_for(lambda: cl.client_id in scene._client_session)  # its connect was seen
        assert scene.flush()  # ... and handled
        assert at_home(cl) and looks_at(cb, 52)

        # A page that follows before it opens its 3D view: nothing moves, the track is not
        # highlighted for the others; its client, once it comes, starts at that track.
        sc = "sessionC-89ab"
        scene.follow(54, follow_body(54, walks[54]), session=sc)
        assert scene.flush()
        assert scene.nodes["/tracks/54/0"].thickness == 4.0
        c3 = FakeViserClient(port, f"/follow/{sc}")
        try:
            c3.send_camera(*home)
            cc = handle(6)
            wait_for(lambda: looks_at(cc, 54))
            assert scene.flush()
            assert scene.nodes["/tracks/54/0"].thickness == 7.0
            assert looks_at(ca, 51) and looks_at(cb, 52) and at_home(cl)
        finally:
            c3.close()
        # ... and when the page is gone its track is drawn as any other again.
        wait_for(lambda: len(scene.server.get_clients()) == 5)
        wait_for(lambda: scene.flush() and scene.nodes["/tracks/54/0"].thickness == 4.0)
        assert scene.follow_state(sc)["track_id"] == 54  # kept for a client that comes back

        # The broadcast (no session): every client follows, the sessions' choices go.
        scene.follow(53, follow_body(53, walks[53]))
        assert scene.flush()
        for c in (ca, cb, cp, ca2, cl):
            assert looks_at(c, 53), c.client_id
        assert scene.follow_state(sa)["track_id"] == 53
        assert scene.nodes["/tracks/51/0"].thickness == 4.0  # no longer followed
        # Session A stops: its cameras stay, the others keep following 53 as it moves.
        scene.follow(None, session=sa)
        assert scene.flush()
        assert scene.follow_state(sa)["track_id"] is None
        assert scene.follow_state(sb)["track_id"] == 53
        assert set(scene._markers) == {cb.client_id, cp.client_id, cl.client_id}
        more = [(5.0, -10.0 - 3.0 * k, 1.0) for k in range(1, 3)]
        upd = follow_body(53, walks[53] + more)
        upd["points"] = upd["points"][len(walks[53]) :]
        upd["first_index"] = len(walks[53])
        scene.publish([TrackUpdateMessage.model_validate(
            {"type": "track_update", "seq": 1, "track": upd}).model_dump()])  # fmt: skip
        assert scene.flush()
        new_head = np.array(more[-1]) + lift
        for c in (cb, cp, cl):
            np.testing.assert_allclose(c.camera.look_at, new_head, atol=1e-9)
        for c in (ca, ca2):
            assert looks_at(c, 53)  # the old head: A stopped there
        with pytest.raises(ValueError, match="bad follow session"):
            scene.follow(1, session="no/slash")
    finally:
        for f in fakes:
            f.close()
        scene.follow(None)
        scene.flush()


def cam_id(scene, session: str) -> int:
    """The id of a session's one client."""
    [k] = scene.follow_state(session)["clients"]
    return int(k["id"])


def test_follow_endpoint(client_factory, sample_site_dir, tmp_path, store_kw):
    from server_helpers import AUTH, make_app, walk

    # Stopped before the next one starts: on PostgreSQL two servers on one database at
    # once are a cluster, where only the lease holder (this one) would track.
    with TestClient(make_app(sample_site_dir, tmp_path, **store_kw)) as plain:
        r = plain.get("/api/scene3d/follow", headers=AUTH)
    assert r.status_code == 404 and "not running" in r.json()["detail"]
    c = client_factory(scene3d=True, viser_port=0)
    r = c.post("/api/detections", json={"detections": walk(n=30)}, headers=AUTH)
    assert r.status_code == 200
    [track] = c.get("/api/tracks", headers=AUTH).json()["tracks"]
    scene = c.app.state.scene3d
    assert scene.wait_ready(120)
    # Every viser client needs a session admitted with the operator token (the gate has
    # its own test below): the "plain" viewer is one that never asks for its own track.
    plain_sid = "plainviewer0001"
    assert (
        c.put("/api/scene3d/session", json={"session": plain_sid}, headers=AUTH).status_code == 200
    )
    viewer = FakeViserClient(scene.server.get_port(), f"/follow/{plain_sid}")
    try:
        viewer.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
        wait_for(lambda: len(scene.server.get_clients()) == 1)
        tid = track["id"]
        assert c.put("/api/scene3d/follow", json={"track_id": tid}).status_code == 401
        bad = c.put("/api/scene3d/follow", json={"track_id": tid + 99}, headers=AUTH)
        assert bad.status_code == 404 and f"no track {tid + 99}" in bad.json()["detail"]
        for body in ({"track_id": -1}, {"track_id": tid, "x": 1}, {}):
            assert c.put("/api/scene3d/follow", json=body, headers=AUTH).status_code == 422
        r = c.put("/api/scene3d/follow", json={"track_id": tid}, headers=AUTH)
        assert r.status_code == 200, r.text
        last = track["points"][-1]
        want = [last["e_m"], last["n_m"], last["u_m"] + 0.4]
        body = r.json()
        assert body["track_id"] == tid
        np.testing.assert_allclose(body["look_at_enu"], want, atol=1e-9)
        [cam] = body["clients"]
        np.testing.assert_allclose(cam["look_at_enu"], want, atol=1e-9)
        assert c.get("/api/scene3d/follow", headers=AUTH).json() == body
        r = c.put("/api/scene3d/follow", json={"track_id": None}, headers=AUTH)
        assert r.status_code == 200 and r.json()["track_id"] is None
        assert r.json()["look_at_enu"] is None
        # A follow session: its own viser client moves, the plain one stays where it is.
        sid = "0123456789abcdef"
        assert c.put("/api/scene3d/session", json={"session": sid}, headers=AUTH).status_code == 200
        mine = FakeViserClient(scene.server.get_port(), f"/follow/{sid}")
        try:
            mine.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
            wait_for(lambda: len(scene.follow_state(sid)["clients"]) == 1)
            viewer.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
            [plain_handle] = [
                h for i, h in scene.server.get_clients().items() if i != cam_id(scene, sid)
            ]
            wait_for(lambda: np.allclose(plain_handle.camera.look_at, 0.0))
            for bad in ("short", "has/slash", "x" * 65, 7):
                body = {"track_id": tid, "session": bad}
                assert c.put("/api/scene3d/follow", json=body, headers=AUTH).status_code == 422
            assert c.get("/api/scene3d/follow?session=short", headers=AUTH).status_code == 422
            body = {"track_id": tid, "session": sid}
            assert c.put("/api/scene3d/follow", json=body).status_code == 401
            r = c.put("/api/scene3d/follow", json=body, headers=AUTH)
            assert r.status_code == 200, r.text
            got = r.json()
            assert got["track_id"] == tid
            [cam] = got["clients"]
            assert cam["session"] == sid and cam["track_id"] == tid
            np.testing.assert_allclose(cam["look_at_enu"], want, atol=1e-9)
            assert c.get(f"/api/scene3d/follow?session={sid}", headers=AUTH).json() == got
            everyone = c.get("/api/scene3d/follow", headers=AUTH).json()
            assert everyone["track_id"] is None and len(everyone["clients"]) == 2
            [other] = [k for k in everyone["clients"] if k["session"] == plain_sid]
            assert other["track_id"] is None
            assert other["look_at_enu"] == [0.0, 0.0, 0.0]  # untouched
            r = c.put("/api/scene3d/follow", json={"track_id": None, "session": sid}, headers=AUTH)
            assert r.status_code == 200 and r.json()["track_id"] is None
        finally:
            mine.close()
        # The OpenAPI schema documents the session (body and query).
        doc = c.get("/openapi.json").json()
        follow_in = doc["components"]["schemas"]["FollowIn"]["properties"]["session"]
        assert "follow session" in follow_in["description"]
        params = doc["paths"]["/api/scene3d/follow"]["get"]["parameters"]
        assert [q["name"] for q in params] == ["session"]
    finally:
        viewer.close()


def test_scene_admits_only_sessions_registered_with_the_operator_token(client_factory):
    """The 3D view needs the operator token as the console does: a viser client whose
    WebSocket names no session admitted through ``PUT /api/scene3d/session`` (token
    required) is closed with 4401 before it is sent anything; an admitted one sees the
    scene."""
    from server_helpers import AUTH
    from websockets.exceptions import ConnectionClosed

    c = client_factory(scene3d=True, viser_port=0)
    scene = c.app.state.scene3d
    assert scene.wait_ready(120)
    port = scene.server.get_port()
    sid = "a1b2c3d4e5f60718"
    # Without the token, or with a malformed session: refused by the API.
    assert c.put("/api/scene3d/session", json={"session": sid}).status_code == 401
    for bad in ("short", "has/slash", "x" * 65, 7, None):
        r = c.put("/api/scene3d/session", json={"session": bad}, headers=AUTH)
        assert r.status_code == 422, (bad, r.text)
    # Not admitted: the root path, an unregistered session. Closed, nothing received.
    for path in ("/", f"/follow/{sid}", "/follow/zzzzzzzzzzzz"):
        ws = FakeViserClient(port, path)
        try:
            wait_for(lambda ws=ws: ws.ws.close_code is not None)
            assert ws.ws.close_code == 4401 and "operator token" in (ws.ws.close_reason or "")
            assert ws.n_received == 0
            with pytest.raises(ConnectionClosed):
                ws.ws.send(b"x")
        finally:
            ws.close()
    assert scene.gate.n_refused >= 3 and not scene.server.get_clients()
    # Admitted with the token: the same session's client gets the scene and is listed.
    r = c.put("/api/scene3d/session", json={"session": sid}, headers=AUTH)
    assert r.status_code == 200 and r.json() == {"session": sid, "websocket_path": f"/follow/{sid}"}
    ok = FakeViserClient(port, f"/follow/{sid}")
    try:
        ok.send_camera(position=(0.0, -200.0, 150.0), look_at=(0.0, 0.0, 0.0))
        wait_for(lambda: len(scene.server.get_clients()) == 1)
        wait_for(lambda: ok.n_received > 0)
        assert ok.ws.close_code is None
    finally:
        ok.close()
