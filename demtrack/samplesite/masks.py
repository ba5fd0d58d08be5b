"""Per-camera ignore masks of the sample site: the tree crowns near enough to look like targets.

The sample videos sway every tree crown by :data:`~.video_scene.SWAY_M` (0.3 m) along the
wind. Far away that is a sub-pixel flicker the VSAM detector's restless test absorbs; near
the mast it moves a crown's texture and outline by several pixels, blobs the size of a
person that come and go. The mask a site operator would paint over those trees is made here
from the world model instead: a pixel is masked when its ray's first hit on the DEM's
surface lies in a tree crown of the analytic world (above the bare earth, under a crown,
as the video renderer decides) nearer than :data:`MASK_RANGE_M`, then the set is dilated by
:data:`DILATE_PX` (the crowns' outline moves into the pixels next to them). A pixel whose
hit is on the bare earth or a roof within :data:`ROUTE_MARGIN_M` of a route the sample
scenarios' targets drive or walk (:data:`~.scenarios.SCENARIOS`) is never masked,
dilation included: a road under an overhanging crown stays open where it is seen. (The
gaps between near crowns elsewhere stay masked: their outline sways into them.)

The rays are cast at a quarter of the image resolution (one ray per 4x4 pixels, about 58
thousand a 1280x720 camera, so the build stays fast) and the mask is brought to full size
by nearest neighbour before the dilation and the ground test (which uses the quarter-size
hits of the same block).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage
from scipy.spatial import cKDTree

from demtrack.core.camera.pinhole import Camera
from demtrack.core.raycast.cast import cast_rays
from demtrack.core.terrain.dem import Dem

from .world import World

__all__ = [
    "DILATE_PX",
    "MASK_RANGE_M",
    "ROUTE_MARGIN_M",
    "STEP_PX",
    "crown_mask",
    "route_points",
    "write_mask",
]

#: Crowns nearer than this (m) are masked: with cam3's focal length (819 px) a 0.3 m sway
#: is 3 px at 80 m and 4-8 px at 30-60 m, where the detector's restless test no longer
#: absorbs the flicker (measured on the sample videos, docs/video.md). The detector's
#: calm-background rule now rejects those crowns too (cam3 scores the same without the
#: mask); the mask stays as what an operator would paint over trees in wind.
MASK_RANGE_M = 80.0
#: The mask grows this far (px) around the near crown pixels.
DILATE_PX = 4
#: One ray per ``STEP_PX`` x ``STEP_PX`` pixels.
STEP_PX = 4
#: Ground within this distance (m) of a target's route is never masked: a car's lane
#: offset (1.5 m) and half its length (2.25 m), with a margin.
ROUTE_MARGIN_M = 5.0


def route_points(world: World, step_m: float = 0.5) -> np.ndarray:
    """Points every ``step_m`` along every sample scenario target's route, ``(n, 2)`` (m)."""
    from .scenarios import SCENARIOS  # the scenarios import the site's rendering

    out = []
    for make in SCENARIOS.values():
        for target in make(world):
            xy = np.asarray(target.motion.route.xy, dtype=np.float64)
            for a, b in zip(xy[:-1], xy[1:], strict=True):
                n = max(1, int(np.ceil(np.hypot(*(b - a)) / step_m)))
                out.append(a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None])
    return np.concatenate(out) if out else np.zeros((0, 2))


def crown_mask(
    camera: Camera, dem: Dem, world: World, *, range_m: float = MASK_RANGE_M
) -> np.ndarray:
    """The ignore mask of ``camera``: near tree crowns (see the module docstring).

    Parameters
    ----------
    camera : Camera
        The camera that makes the video (the true mount yaw, as the sample videos use).
    dem : Dem
        The site's first-return DEM.
    world : World
        The analytic world it was generated from (which hits are crowns).
    range_m : float
        Crowns nearer than this (m) are masked.

    Returns
    -------
    ndarray of bool, shape (h, w)
        True where detections are ignored, image pixels.
    """
    h, w = camera.intrinsics.height, camera.intrinsics.width
    rows = np.arange(STEP_PX // 2, h, STEP_PX)
    cols = np.arange(STEP_PX // 2, w, STEP_PX)
    v, u = np.meshgrid(rows, cols, indexing="ij")
    origins, dirs = camera.pixel_to_ray(u.ravel().astype(float), v.ravel().astype(float))
    hits = cast_rays(dem, origins, dirs, 5000.0, mode="first", coherent=False)
    rng_m = hits.first_range_m()
    has = np.isfinite(rng_m)
    p = hits.first_points()
    crown = np.zeros(len(rng_m), bool)
    ground = np.zeros(len(rng_m), bool)
    crown_z = world.crown_z(p[has, 0], p[has, 1])
    ground_z = world.ground_z(p[has, 0], p[has, 1])
    in_crown = np.isfinite(crown_z) & (p[has, 2] > ground_z + 1.0)
    crown[has] = in_crown & (rng_m[has] < range_m)
    on_route = np.zeros(int(has.sum()), bool)
    routes = route_points(world)
    if len(routes):
        dist, _ = cKDTree(routes).query(p[has, :2], distance_upper_bound=ROUTE_MARGIN_M)
        on_route = np.isfinite(dist)
    ground[has] = ~in_crown & on_route  # bare earth or a roof where targets go
    shape = (len(rows), len(cols))

    def full(small: np.ndarray) -> np.ndarray:
        big = np.repeat(np.repeat(small.reshape(shape), STEP_PX, axis=0), STEP_PX, axis=1)
        return big[:h, :w]

    near = ndimage.binary_dilation(full(crown), iterations=DILATE_PX)
    # a block whose ray hit a target's ground stays open, dilation or not (a block
    # straddling a crown's edge is masked when its ray saw the crown)
    return near & ~full(ground)


def write_mask(path: str | Path, mask: np.ndarray) -> Path:
    """Write ``mask`` as the PNG the detector reads (white = ignore, 8-bit grey)."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(out)
    return out
