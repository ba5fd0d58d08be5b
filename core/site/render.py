"""Synthetic camera views: ray-cast the DEM and drape the orthophoto.

Every pixel's viewing ray is cast against the terrain surface (first hit); the hit takes
the orthophoto colour below it, shaded by the surface slope towards a sun direction and
faded into haze with range. Rays that miss see a sky gradient. This gives an operator
an image to click on for any site and pose, and lets tests check geolocation against a
picture whose geometry is known exactly.
"""

from __future__ import annotations

import numpy as np

from ..camera.pinhole import Camera
from ..raycast.cast import cast_rays
from ..terrain.dem import Dem
from ..terrain.grid import GridSpec

__all__ = ["render_view"]

SKY_ZENITH = np.array([110.0, 150.0, 205.0])
SKY_HORIZON = np.array([200.0, 215.0, 230.0])
NO_IMAGE = np.array([128.0, 128.0, 128.0])


def _drape(rgb: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Orthophoto colour (float RGB) under each point; grey off the image."""
    rows, cols = grid.cell_of(x, y)
    out = np.tile(NO_IMAGE, (len(x), 1))
    ok = rows >= 0
    out[ok] = rgb[rows[ok], cols[ok], :3]
    return out


def render_view(
    camera: Camera,
    dem: Dem,
    ortho_rgb: np.ndarray,
    ortho_grid: GridSpec,
    *,
    sun_az_deg: float = 200.0,
    sun_elev_deg: float = 45.0,
    haze_m: float = 2500.0,
    max_range_m: float = 5000.0,
) -> np.ndarray:
    """Render what ``camera`` sees of the DEM draped with the orthophoto.

    Parameters
    ----------
    camera : Camera
    dem : Dem
    ortho_rgb : ndarray, uint8, shape (rows, cols, 3 or 4)
        Orthophoto on ``ortho_grid`` (site frame).
    ortho_grid : GridSpec
    sun_az_deg, sun_elev_deg : float
        Sun direction for Lambert shading (degrees; azimuth clockwise from north).
    haze_m : float
        Range at which the haze takes 63 % of the colour.
    max_range_m : float
        Rays are followed this far.

    Returns
    -------
    ndarray, uint8, shape (height, width, 3)
    """
    intr = camera.intrinsics
    v, u = np.mgrid[0 : intr.height, 0 : intr.width]
    origins, dirs = camera.pixel_to_ray(u.ravel(), v.ravel())
    # One cast per camera (site build): the angular index's build and its one-time kernel
    # compile (about a minute of CPU on a cold numba cache) cost more than it saves here.
    hits = cast_rays(dem, origins, dirs, max_range_m, mode="first", coherent=False)
    p = hits.first_points()
    has = np.isfinite(p[:, 0])
    # Sky: blend from horizon to zenith with the ray's elevation.
    t = np.clip(dirs[:, 2] * 3.0, 0.0, 1.0)[:, None]
    colour = SKY_HORIZON * (1 - t) + SKY_ZENITH * t
    x, y = p[has, 0], p[has, 1]
    base = _drape(ortho_rgb, ortho_grid, x, y)
    gx, gy = dem.gradient(x, y)
    normal = np.column_stack([-np.nan_to_num(gx), -np.nan_to_num(gy), np.ones(len(x))])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    az, el = np.radians(sun_az_deg), np.radians(sun_elev_deg)
    sun = np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    lambert = np.clip(normal @ sun, 0.0, 1.0)
    shaded = base * (0.7 + 0.4 * lambert)[:, None]
    rng = np.linalg.norm(p[has] - origins[has], axis=1)
    fade = (1.0 - np.exp(-rng / haze_m))[:, None]
    colour[has] = shaded * (1 - fade) + SKY_HORIZON * fade
    return np.clip(colour, 0, 255).astype(np.uint8).reshape(intr.height, intr.width, 3)
