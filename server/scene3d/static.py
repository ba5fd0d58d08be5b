"""The static scene: the starting view, the textured terrain, the sensors' frusta, the roads.

Built once, on the scene thread, when the scene starts: the DEM as a mesh (decimated to a
few hundred vertices a side) textured with the orthophoto (or coloured by height without
one), each sensor's camera as a frustum at its pose with its still on the image plane and
a label, and the road centre lines draped on the DEM. Also viser's control panel, kept out
of the view.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from demtrack.core.site.folder import Site

from .frusta import frustum_fov_aspect, wxyz_from_matrix
from .geometry import polyline_segments, road_polylines, terrain_mesh, texture_uv
from .style import sensor_colour

__all__ = ["build_static", "configure_gui"]


def configure_gui(server: Any) -> None:
    """Keep viser's control panel out of the view: small, no logo, minimised.

    The console embeds the scene in a tab about 640 px wide at 1280 x 800; viser's
    panel (scene tree, camera tools) stays one click away in its minimised bar.
    Theme and placement are persistent messages, so later clients get them too.

    Parameters
    ----------
    server : viser.ViserServer
    """
    gui = server.gui
    gui.configure_theme(
        control_width="small", show_logo=False, show_share_button=False, dark_mode=True
    )
    gui.main_panel.minimize()


def build_static(
    server: Any, site: Site, nodes: dict[str, Any], *, mesh_side: int, texture_px: int
) -> tuple[np.ndarray, np.ndarray]:
    """Set the starting view and draw the terrain, the sensors and the roads.

    Parameters
    ----------
    server : viser.ViserServer
    site : Site
    nodes : dict
        Scene node name -> viser handle: the nodes drawn go in.
    mesh_side : int
        Most terrain vertices per side.
    texture_px : int
        Largest side of the orthophoto texture (px).

    Returns
    -------
    position, look_at : ndarray, shape (3,)
        The starting view every client gets (``initial_camera``, site frame m).
    """
    scene = server.scene
    g = site.dem.grid
    lo, hi = site.dem.elevation_range()
    span = max(g.ncols, g.nrows) * g.cell_m
    cam = server.initial_camera
    cx, cy = 0.5 * (g.bounds[0] + g.bounds[2]), 0.5 * (g.bounds[1] + g.bounds[3])
    cam.position = (cx, cy - 0.65 * span, hi + 0.45 * span)
    cam.look_at = (cx, cy, lo)
    home = (np.asarray(cam.position, float), np.asarray(cam.look_at, float))
    cam.up = (0.0, 0.0, 1.0)
    cam.near = 0.5
    cam.far = 20.0 * span
    _add_terrain(server, site, nodes, mesh_side, texture_px)
    for k, sensor in enumerate(sorted(site.sensors.values(), key=lambda s: s.id)):
        _add_camera(server, nodes, sensor, sensor_colour(k), span)
    roads = road_polylines(site)
    if roads:
        segs = np.concatenate([polyline_segments(p) for p in roads])
        nodes["/roads"] = scene.add_line_segments(
            "/roads", segs, (250, 250, 250), thickness=3.0, thickness_units="screen"
        )
    return home


def _add_terrain(
    server: Any, site: Site, nodes: dict[str, Any], mesh_side: int, texture_px: int
) -> None:
    import trimesh
    from PIL import Image

    from demtrack.core.site.orthophoto import read_orthophoto

    mesh = terrain_mesh(site.dem, mesh_side)
    visual: Any = None
    if site.orthophoto_path is not None:
        rgb, grid = read_orthophoto(site.orthophoto_path)
        image = Image.fromarray(rgb)
        image.thumbnail((texture_px, texture_px))
        uv = texture_uv(mesh.vertices[:, :2], grid)
        material = trimesh.visual.material.SimpleMaterial(image=image, diffuse=(255,) * 4)
        visual = trimesh.visual.TextureVisuals(uv=uv, image=image, material=material)
    else:
        z = mesh.vertices[:, 2]
        t = (z - z.min()) / max(float(np.ptp(z)), 1e-9)
        colours = np.column_stack([80 + 120 * t, 140 + 60 * t, 80 + 40 * t, np.full_like(t, 255)])
        visual = trimesh.visual.ColorVisuals(vertex_colors=colours.astype(np.uint8))
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, visual=visual, process=False)
    nodes["/terrain"] = server.scene.add_mesh_trimesh("/terrain", tm)


def _add_camera(
    server: Any, nodes: dict[str, Any], sensor: Any, colour: tuple[int, int, int], span: float
) -> None:
    scene = server.scene
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
    nodes[name] = scene.add_camera_frustum(
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
    )
    label = f"/labels/{sensor.id}"
    nodes[label] = scene.add_label(
        label,
        f"{sensor.id} ({sensor.name})",
        position=np.asarray(camera.position_enu, dtype=np.float64) + [0.0, 0.0, 3.0],
    )
