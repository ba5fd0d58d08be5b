"""Sensor frusta: a camera's pose and field of view as viser draws them.

viser's frustums follow the OpenCV camera convention (x right, y down, z forward), the same
as ``R_world_cam``, so a frustum's orientation is ``R_world_cam`` as a quaternion; its
``fov`` and ``aspect`` come from the undistorted image edges.

A PTZ sensor's frustum follows its pose telemetry: :class:`FrustumPoses` keeps each
sensor's newest ``sensor_pose`` message and, once per scene render (every
``update_s``, 0.25 s), turns, moves and re-zooms its frustum to the camera at that pose
(:func:`~demtrack.core.camera.pose_series.camera_at`). The still on a moved frustum is
taken off: it shows the fixed view, not the moving camera's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.site.folder import Sensor

__all__ = ["FrustumPoses", "frustum_fov_aspect", "pose_camera", "wxyz_from_matrix"]


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


def pose_camera(sensor: Sensor, msg: Mapping[str, Any]) -> Camera:
    """The camera of ``sensor`` at the pose of a ``sensor_pose`` message."""
    pose = PoseSample(
        float(msg["t_s"]),
        float(msg["pan_deg"]),
        float(msg["tilt_deg"]),
        hfov_deg=msg.get("hfov_deg"),
        roll_deg=float(msg.get("roll_deg") or 0.0),
    )
    return camera_at(sensor.head, pose, getattr(sensor, "zoom", None))


class FrustumPoses:
    """Each sensor's newest pose, applied to its frustum when the scene renders.

    Parameters
    ----------
    sensors : mapping of str to Sensor
        The site's sensors.
    nodes : dict
        The scene's handles (``/cameras/<id>``: the frustum, ``/labels/<id>``: its label).
    """

    def __init__(self, sensors: Mapping[str, Sensor], nodes: dict[str, Any]) -> None:
        self.sensors = sensors
        self.nodes = nodes
        self._pending: dict[str, Mapping[str, Any]] = {}
        #: Frustum moves made (a burst of poses between renders is one move).
        self.n_moves = 0

    def offer(self, msg: Mapping[str, Any]) -> None:
        """Keep a ``sensor_pose`` message (the newer replaces the older)."""
        sid = msg.get("sensor")
        if isinstance(sid, str) and sid in self.sensors:
            self._pending[sid] = msg

    def render(self) -> None:
        """Move the frusta of the sensors whose pose changed since the last render."""
        pending, self._pending = self._pending, {}
        for sid, msg in sorted(pending.items()):
            handle = self.nodes.get(f"/cameras/{sid}")
            if handle is None:
                continue
            cam = pose_camera(self.sensors[sid], msg)
            fov, aspect = frustum_fov_aspect(cam.intrinsics)
            position = np.asarray(cam.position_enu, dtype=np.float64)
            handle.wxyz = wxyz_from_matrix(cam.R_world_cam)
            handle.position = position
            handle.fov = fov
            handle.aspect = aspect
            if handle.image is not None:
                handle.image = None
            label = self.nodes.get(f"/labels/{sid}")
            if label is not None:
                label.position = position + [0.0, 0.0, 3.0]
            self.n_moves += 1
