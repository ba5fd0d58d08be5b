"""The viser 3D scene: geometry helpers against independent references, and a live scene."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from demtrack.core.dem import Dem
from demtrack.core.grid import GridSpec
from demtrack.core.site import load_site
from demtrack.server.messages import FixMessage, TrackUpdateMessage
from demtrack.server.scene3d import (
    Scene3D,
    display_host,
    frustum_fov_aspect,
    polyline_segments,
    road_polylines,
    terrain_mesh,
    texture_uv,
    wxyz_from_matrix,
)

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
    sc = Scene3D(site, host="127.0.0.1", port=0, max_rays=5)
    assert sc.wait_ready(120) and sc.error is None
    yield sc
    sc.stop()


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
    assert {"/rays/lines", "/rays/hits", "/rays/chosen", "/tracks/7"} <= set(scene.nodes)
    chosen = np.asarray(scene.nodes["/rays/chosen"].points)
    np.testing.assert_allclose(chosen, [[20.0, 0.0, 3.0], [11.0, 1.0, 15.0]])
    assert len(scene.nodes["/rays/hits"].points) == 4
    lines = np.asarray(scene.nodes["/rays/lines"].points)
    np.testing.assert_allclose(lines[0], [[0.0, 0.0, 30.0], [20.0, 0.0, 3.0]])  # to the far hit
    track = np.asarray(scene.nodes["/tracks/7"].points)
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
    track = np.asarray(scene.nodes["/tracks/7"].points)
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
