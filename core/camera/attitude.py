"""Attitude arithmetic on arrays: rotations from angles, unit quaternions, slerp.

Batched forms of the rotations the pose model uses (``core.camera.pose_series``):

* :func:`rotations_from_azimuth_tilt_roll` is
  :func:`~demtrack.core.camera.pinhole.rotation_from_azimuth_tilt_roll` for ``n`` angle
  triples at once (the same formulas; columns are the camera's x right, y down,
  z forward axes).
* :func:`rotations_from_ypr`: a platform's ``R_world_body`` from yaw (clockwise from
  true north), pitch (+ nose up), roll (+ right wing down), body axes x right, y forward,
  z up: ``Rz(-yaw) Rx(pitch) Ry(roll)`` with right-handed rotations about E, N, U.
  :func:`ypr_from_rotation` inverts it (pitch in [-90, 90], yaw and roll in (-180, 180]).
* Quaternions are ``(w, x, y, z)``, unit, scalar first; :func:`slerp` takes the short arc.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "quat_from_rotation",
    "rotation_from_quat",
    "rotations_from_azimuth_tilt_roll",
    "rotations_from_ypr",
    "slerp",
    "ypr_from_rotation",
]


def rotations_from_azimuth_tilt_roll(
    az_deg: np.ndarray, tilt_deg: np.ndarray, roll_deg: np.ndarray
) -> np.ndarray:
    """``R_world_cam`` for each (azimuth, tilt, roll) in degrees, shape (n, 3, 3).

    Columns: right ``cos(roll) r0 + sin(roll) d0``, down ``cos(roll) d0 - sin(roll) r0``
    and forward ``(sin az cos t, cos az cos t, sin t)``, where ``r0 = (cos az, -sin az, 0)``
    is the level right of the azimuth and ``d0 = forward x r0 = (sin t sin az,
    sin t cos az, -cos t)``.
    """
    az, tilt, roll = (
        np.radians(np.asarray(a, dtype=np.float64).reshape(-1))
        for a in (az_deg, tilt_deg, roll_deg)
    )
    sa, ca = np.sin(az), np.cos(az)
    st, ct = np.sin(tilt), np.cos(tilt)
    sr, cr = np.sin(roll), np.cos(roll)
    out = np.empty((len(az), 3, 3))
    d0x, d0y, d0z = st * sa, st * ca, -ct
    out[:, 0, 0] = cr * ca + sr * d0x
    out[:, 1, 0] = -cr * sa + sr * d0y
    out[:, 2, 0] = sr * d0z
    out[:, 0, 1] = cr * d0x - sr * ca
    out[:, 1, 1] = cr * d0y + sr * sa
    out[:, 2, 1] = cr * d0z
    out[:, 0, 2] = sa * ct
    out[:, 1, 2] = ca * ct
    out[:, 2, 2] = st
    return out


def rotations_from_ypr(ypr_deg: np.ndarray) -> np.ndarray:
    """Platform ``R_world_body`` for each (yaw, pitch, roll) row in degrees, shape (n, 3, 3)."""
    ypr = np.radians(np.asarray(ypr_deg, dtype=np.float64).reshape(-1, 3))
    sy, cy = np.sin(ypr[:, 0]), np.cos(ypr[:, 0])
    sp, cp = np.sin(ypr[:, 1]), np.cos(ypr[:, 1])
    sr, cr = np.sin(ypr[:, 2]), np.cos(ypr[:, 2])
    n = len(ypr)
    o, z = np.ones(n), np.zeros(n)
    # Rz(-yaw): clockwise seen from above.
    rz = np.stack(
        [np.stack([cy, sy, z], -1), np.stack([-sy, cy, z], -1), np.stack([z, z, o], -1)], 1
    )
    rx = np.stack(
        [np.stack([o, z, z], -1), np.stack([z, cp, -sp], -1), np.stack([z, sp, cp], -1)], 1
    )
    ry = np.stack(
        [np.stack([cr, z, sr], -1), np.stack([z, o, z], -1), np.stack([-sr, z, cr], -1)], 1
    )
    return rz @ rx @ ry


def ypr_from_rotation(r: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotations_from_ypr`: (yaw, pitch, roll) degrees, shape (n, 3).

    At pitch +-90 yaw and roll are not separable; roll is then 0.
    """
    r = np.asarray(r, dtype=np.float64).reshape(-1, 3, 3)
    forward = r[:, :, 1]  # the body y axis (nose) in ENU
    pitch = np.degrees(np.arcsin(np.clip(forward[:, 2], -1.0, 1.0)))
    yaw = np.degrees(np.arctan2(forward[:, 0], forward[:, 1]))
    # Roll: the body x axis (right wing) against the level right of the nose.
    right = r[:, :, 0]
    level_right = np.stack(
        [np.cos(np.radians(yaw)), -np.sin(np.radians(yaw)), np.zeros(len(r))], -1
    )
    up0 = np.cross(level_right, forward)
    roll = np.degrees(np.arctan2(-np.sum(right * up0, -1), np.sum(right * level_right, -1)))
    vertical = np.hypot(forward[:, 0], forward[:, 1]) < 1e-12
    if vertical.any():
        # Nose straight up or down: take the yaw the right wing implies, roll 0.
        yaw[vertical] = np.degrees(np.arctan2(-right[vertical, 1], right[vertical, 0]))
        roll[vertical] = 0.0
    out = np.stack([yaw, pitch, roll], axis=-1)
    out[:, [0, 2]] = np.where(out[:, [0, 2]] <= -180.0, out[:, [0, 2]] + 360.0, out[:, [0, 2]])
    return out


def quat_from_rotation(r: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` (w >= 0) of rotation matrices ``(n, 3, 3)``.

    Shepperd's method: the largest of the four squared components is taken from the
    trace or a diagonal entry, so no division by a small number.
    """
    r = np.asarray(r, dtype=np.float64).reshape(-1, 3, 3)
    n = len(r)
    tr = np.trace(r, axis1=1, axis2=2)
    diag = np.stack([tr, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], -1)
    pick = np.argmax(diag, axis=1)
    q = np.empty((n, 4))
    for c in range(4):
        m = pick == c
        if not m.any():
            continue
        rr = r[m]
        if c == 0:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack(
                [0.25 * s, (rr[:, 2, 1] - rr[:, 1, 2]) / s, (rr[:, 0, 2] - rr[:, 2, 0]) / s,
                 (rr[:, 1, 0] - rr[:, 0, 1]) / s], -1)  # fmt: skip
            continue
        i = c - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(np.maximum(1.0 + rr[:, i, i] - rr[:, j, j] - rr[:, k, k], 0.0))
        qi = np.empty((len(rr), 4))
        qi[:, 0] = (rr[:, k, j] - rr[:, j, k]) / s
        qi[:, 1 + i] = 0.25 * s
        qi[:, 1 + j] = (rr[:, j, i] + rr[:, i, j]) / s
        qi[:, 1 + k] = (rr[:, k, i] + rr[:, i, k]) / s
        q[m] = qi
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0.0, -q, q)


def rotation_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` of quaternions ``(w, x, y, z)`` (normalised here)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation ``q0 -> q1`` at fractions ``a``, the short arc: (n, 4).

    Exactly ``q0`` where ``a`` is 0; nearly parallel pairs (angle under 1e-9 rad) fall
    back to the normalised linear blend.
    """
    q0 = np.asarray(q0, dtype=np.float64).reshape(-1, 4)
    q1 = np.asarray(q1, dtype=np.float64).reshape(-1, 4)
    a = np.asarray(a, dtype=np.float64).reshape(-1)
    dot = np.sum(q0 * q1, axis=1)
    q1 = np.where((dot < 0.0)[:, None], -q1, q1)  # q and -q are one rotation: short way
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-9
    sin_t = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * theta) / sin_t)
    w1 = np.where(small, a, np.sin(a * theta) / sin_t)
    out = w0[:, None] * q0 + w1[:, None] * q1
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    return np.where((a == 0.0)[:, None], q0, out)
