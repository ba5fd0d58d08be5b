"""Sensor frusta: a camera's pose and field of view as viser draws them.

viser's frustums follow the OpenCV camera convention (x right, y down, z forward), the same
as ``R_world_cam``, so a frustum's orientation is ``R_world_cam`` as a quaternion; its
``fov`` and ``aspect`` come from the undistorted image edges.
"""

from __future__ import annotations

import math

import numpy as np

from demtrack.core.camera.pinhole import Intrinsics

__all__ = ["frustum_fov_aspect", "wxyz_from_matrix"]


def wxyz_from_matrix(R: np.ndarray) -> np.ndarray:  # noqa: N803 - a rotation matrix is R
    """Unit quaternion ``(w, x, y, z)`` (``w >= 0``) of a proper rotation matrix.

    viser's own conversion (:meth:`viser.transforms.SO3.from_matrix`), with the sign
    chosen so that ``w >= 0``: viser returns either of ``q`` and ``-q`` (the same
    rotation), depending on which of its four branches it takes.

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        Rotation (orthonormal, determinant +1), e.g. ``R_world_cam``.

    Returns
    -------
    ndarray, shape (4,)
    """
    # viser is imported with the scene, not with this module (the CLI imports the package)
    from viser.transforms import SO3

    q = np.asarray(SO3.from_matrix(np.asarray(R, dtype=np.float64)).wxyz)
    return -q if q[0] < 0 else q


def frustum_fov_aspect(intrinsics: Intrinsics) -> tuple[float, float]:
    """Viser's frustum ``(fov, aspect)``: vertical field of view (rad), width / height.

    From the undistorted image edges (the image spans ``u in [-0.5, width - 0.5]``,
    ``v in [-0.5, height - 0.5]``) through the principal point, so the frustum's edges
    are the rays of the image's edge midpoints when the principal point is centred and
    the distortion radial.

    Parameters
    ----------
    intrinsics : Intrinsics
        The camera's pinhole and distortion model (pixels).

    Returns
    -------
    fov : float
        Vertical field of view (rad).
    aspect : float
        Width over height of the undistorted image plane.
    """
    i = intrinsics
    xn, yn = i.undistort(
        np.array([-0.5, i.width - 0.5, i.cx, i.cx]), np.array([i.cy, i.cy, -0.5, i.height - 0.5])
    )
    tan_x = 0.5 * float(xn[1] - xn[0])
    tan_y = 0.5 * float(yn[3] - yn[2])
    return 2.0 * math.atan(tan_y), tan_x / tan_y
