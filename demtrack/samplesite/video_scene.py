"""What a fixed sample camera sees that does not move: background, depth, tree crowns.

A sample camera never moves, so its static scene is computed once: the draped terrain
(:func:`~demtrack.core.site.render.render_view`, the same picture as the site's still),
each pixel's viewing ray, and the range along it to the DEM's first-return surface (the
depth image that hides targets behind crowns, roofs and ridges). The pixels whose ray
ends in a tree crown of the analytic world (hit above the bare earth, under a crown) get
a sway field: per frame they take their colour from a point displaced along the wind,
by a fraction of a metre at their range, each tree with its own phase, so the crowns'
texture and outline move a little and a naive change detector sees clutter there.

Targets are boxes (:data:`~.scenarios.SIZES_M`) standing on the true ground, their
bottom on the ground's tangent plane under the centre (a parallelepiped), intersected
exactly with each pixel's ray (:func:`box_hits`): the nearest face, its range and its
outward normal for flat shading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from demtrack.core.camera.pinhole import Camera
from demtrack.core.errors import SiteError
from demtrack.core.raycast.cast import cast_rays
from demtrack.core.site.folder import Site
from demtrack.core.site.orthophoto import read_orthophoto
from demtrack.core.site.render import render_view

from .world import World

__all__ = ["BoxPose", "CameraScene", "box_corners", "box_hits", "camera_scene"]

#: Sway of a crown's foliage along the wind (m, amplitude) and the wind's azimuth (deg).
SWAY_M = 0.3
WIND_AZ_DEG = 250.0
#: A crown's outline moves into the pixels this close to it (px).
SWAY_REACH_PX = 3


@dataclass(frozen=True, eq=False)
class CameraScene:
    """One camera's static view.

    Parameters
    ----------
    camera : Camera
        The true camera (true mount yaw).
    background : ndarray, float32, shape (h, w, 3)
        The draped terrain, RGB 0..255.
    range_m : ndarray, float64, shape (h, w)
        Range along each pixel's ray to the DEM's first-return surface (m; inf: sky).
    directions : ndarray, float64, shape (h, w, 3)
        Unit viewing ray of each pixel (ENU); pixel (0, 0) is the top-left pixel's centre.
    sway_rows, sway_cols : ndarray of int, shape (n,)
        Pixels in or next to a crown, whose colour sways.
    sway_du, sway_dv : ndarray, float32, shape (n,)
        Image displacement (px) of a crown point moved :data:`SWAY_M` along the wind.
    sway_tree : ndarray of int, shape (n,)
        Index of the tree each swaying pixel belongs to (its phase).
    """

    camera: Camera
    background: np.ndarray
    range_m: np.ndarray
    directions: np.ndarray
    sway_rows: np.ndarray
    sway_cols: np.ndarray
    sway_du: np.ndarray
    sway_dv: np.ndarray
    sway_tree: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """Image (rows, columns)."""
        return self.range_m.shape  # type: ignore[return-value]


def camera_scene(site: Site, world: World, camera: Camera) -> CameraScene:
    """Render the static view of ``camera`` (about one DEM ray cast per pixel, twice).

    Parameters
    ----------
    site : Site
        The sample site (DEM and orthophoto).
    world : World
        Its analytic world (which surface hits are tree crowns).
    camera : Camera
        A fixed camera, normally the true one (:func:`~.scenarios.true_cameras`).
    """
    if site.orthophoto_path is None:
        raise SiteError(f"{site.root} has no orthophoto to drape")
    rgb, grid = read_orthophoto(site.orthophoto_path)
    background = render_view(camera, site.dem, rgb, grid).astype(np.float32)
    h, w = camera.intrinsics.height, camera.intrinsics.width
    v, u = np.mgrid[0:h, 0:w]
    origins, dirs = camera.pixel_to_ray(u.ravel(), v.ravel())
    hits = cast_rays(site.dem, origins, dirs, 5000.0, mode="first", coherent=False)
    rng_m = hits.first_range_m()
    range_m = np.where(np.isfinite(rng_m), rng_m, np.inf)
    p = hits.first_points()
    has = np.isfinite(rng_m)
    crown = np.zeros(h * w, dtype=bool)
    crown_z = world.crown_z(p[has, 0], p[has, 1])
    ground_z = world.ground_z(p[has, 0], p[has, 1])
    crown[has] = np.isfinite(crown_z) & (p[has, 2] > ground_z + 1.0)
    crown_img = crown.reshape(h, w)
    # Each pixel near a crown takes the sway of the nearest crown pixel: the outline moves.
    _, (ni, nj) = ndimage.distance_transform_edt(~crown_img, return_indices=True)
    near = ndimage.binary_dilation(crown_img, iterations=SWAY_REACH_PX)
    rows, cols = np.nonzero(near)
    src = ni[rows, cols] * w + nj[rows, cols]
    az = np.radians(WIND_AZ_DEG)
    wind = np.array([np.sin(az), np.cos(az), 0.0]) * SWAY_M
    pc = p[src]
    u0, v0, _ = camera.project(pc)
    u1, v1, _ = camera.project(pc + wind)
    tree_xy = np.array([[t.x, t.y] for t in world.trees]) if world.trees else np.zeros((1, 2))
    d2 = (pc[:, None, 0] - tree_xy[None, :, 0]) ** 2 + (pc[:, None, 1] - tree_xy[None, :, 1]) ** 2
    return CameraScene(
        camera=camera,
        background=background,
        range_m=range_m.reshape(h, w),
        directions=dirs.reshape(h, w, 3),
        sway_rows=rows,
        sway_cols=cols,
        sway_du=np.nan_to_num(u1 - u0).astype(np.float32),
        sway_dv=np.nan_to_num(v1 - v0).astype(np.float32),
        sway_tree=np.argmin(d2, axis=1) if len(pc) else np.zeros(0, dtype=np.int64),
    )


@dataclass(frozen=True)
class BoxPose:
    """A target box at one instant (site frame, m).

    Parameters
    ----------
    xy : tuple of 2 float
        Footprint centre.
    heading : tuple of 2 float
        Unit heading (the length axis).
    size_m : tuple of 3 float
        Length, width, height.
    z0 : float
        True ground height under the centre.
    slope : tuple of 2 float
        Ground gradient (dz/dx, dz/dy) under the centre: the bottom lies on that plane.
    """

    xy: tuple[float, float]
    heading: tuple[float, float]
    size_m: tuple[float, float, float]
    z0: float
    slope: tuple[float, float]

    def affine(self) -> tuple[np.ndarray, np.ndarray]:
        """``(A, c0)``: box coordinates ``q = A @ (p - c0)``; inside is [-.5,.5]^2 x [0,1]."""
        hx, hy = self.heading
        length, width, height = self.size_m
        gx, gy = self.slope
        a = np.array(
            [
                [hx / length, hy / length, 0.0],
                [hy / width, -hx / width, 0.0],  # right of the heading
                [-gx / height, -gy / height, 1.0 / height],
            ]
        )
        return a, np.array([self.xy[0], self.xy[1], self.z0])


def box_corners(pose: BoxPose) -> np.ndarray:
    """The 8 corners of the box (site frame, m), shape (8, 3)."""
    a, c0 = pose.affine()
    q = np.array([[i, j, k] for i in (-0.5, 0.5) for j in (-0.5, 0.5) for k in (0.0, 1.0)])
    return q @ np.linalg.inv(a).T + c0


def box_hits(
    pose: BoxPose, origin: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intersect rays with a target box (slab method in the box's own coordinates).

    Parameters
    ----------
    pose : BoxPose
    origin : ndarray, shape (3,)
        The camera centre (m).
    directions : ndarray, shape (..., 3)
        Unit ray directions.

    Returns
    -------
    range_m : ndarray, shape (...)
        Range to the entry point (m); inf where the ray misses the box.
    normal : ndarray, shape (..., 3)
        Outward unit normal of the entry face (world frame).
    height : ndarray, shape (...)
        Height of the entry point within the box, 0 (bottom) to 1 (top).
    """
    a, c0 = pose.affine()
    q0 = a @ (np.asarray(origin, dtype=np.float64) - c0)
    dq = directions @ a.T
    lo = np.array([-0.5, -0.5, 0.0])
    hi = np.array([0.5, 0.5, 1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - q0) / dq
        t2 = (hi - q0) / dq
    # A ray parallel to a slab: inside it for every t, or outside it for every t.
    inside = (q0 >= lo) & (q0 <= hi)
    parallel = dq == 0
    tmin = np.where(parallel, np.where(inside, -np.inf, np.inf), np.fmin(t1, t2))
    tmax = np.where(parallel, np.where(inside, np.inf, -np.inf), np.fmax(t1, t2))
    axis = np.argmax(tmin, axis=-1)
    t_near = np.take_along_axis(tmin, axis[..., None], axis=-1)[..., 0]
    t_far = tmax.min(axis=-1)
    hit = (t_near <= t_far) & (t_near > 0)
    # Entry through the low side of the slab when the ray runs up that axis.
    sign = np.where(np.take_along_axis(dq, axis[..., None], axis=-1)[..., 0] > 0, -1.0, 1.0)
    normal = a[axis] * sign[..., None]
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    height = q0[2] + np.where(hit, t_near, 0.0) * dq[..., 2]
    return np.where(hit, t_near, np.inf), normal, height
