"""The viser 3D scene: terrain, cameras, roads, and the live rays, hits and tracks.

Everything is in the site frame (x east, y north, z up, m), which is viser's default
``+z`` up world. :class:`Scene3D` (:mod:`.scene`) owns the viser server and its update
thread; the static scene is built by :mod:`.static` from the pure geometry of
:mod:`.geometry` (terrain mesh, texture coordinates, roads) and :mod:`.frusta` (camera
poses and fields of view); the live layers are :mod:`.rays` and :mod:`.tracks`, coloured by
:mod:`.style`; :mod:`.following` moves the cameras of clients that follow a track, each
client's follow session read from its WebSocket path (:mod:`.connections`). May import
``demtrack.core`` (camera, site, terrain), viser, trimesh and PIL, and no other part of
``demtrack.server``; viser, trimesh and PIL only when a scene starts, so that importing the
package stays cheap.
"""

from __future__ import annotations

from .connections import FOLLOW_PATH, SESSION_PATTERN, display_host, session_of_path
from .following import FOLLOW_OFFSET_M, follow_offset
from .frusta import frustum_fov_aspect, wxyz_from_matrix
from .geometry import TerrainMesh, polyline_segments, road_polylines, terrain_mesh, texture_uv
from .scene import Scene3D
from .style import class_colour, sensor_colour

__all__ = [
    "FOLLOW_OFFSET_M",
    "FOLLOW_PATH",
    "SESSION_PATTERN",
    "Scene3D",
    "TerrainMesh",
    "class_colour",
    "display_host",
    "follow_offset",
    "frustum_fov_aspect",
    "polyline_segments",
    "road_polylines",
    "sensor_colour",
    "session_of_path",
    "terrain_mesh",
    "texture_uv",
    "wxyz_from_matrix",
]
