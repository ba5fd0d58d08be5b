"""The ray gate: whether a fix's viewing ray passes through a track's predicted position.

A camera fix is a ray; its terrain hits are where the ray meets the DEM. Near a crest, or
where the DEM and the ground disagree by a few decimetres, the ray of a box on a known
object can miss the object's own crossing (only a hit 20-30 m farther on remains) or
meet the ground metres away along the ray. Such a fix is still that object's box, seen
by the same camera along the same line of sight: the tracker must not take it for a new
object (it would seed a track that shadows the real one along the ray: a phantom). The
ray gate says whether a ray passes through a track's gate: horizontally within the
chi-square gate of the track's predicted position (the point of the ray's ground track
closest in the Mahalanobis metric), and vertically within ``dz_max_m`` of the track's
ground height there (a ray to an object farther behind passes above the track).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ray_gate"]


def ray_gate(
    origin_enu: np.ndarray,
    direction_enu: np.ndarray,
    mean_xy: np.ndarray,
    cov_xy: np.ndarray,
    z_m: np.ndarray,
    gate_d2: float,
    dz_max_m: float,
) -> np.ndarray:
    """Whether the ray passes through the gate of each of ``n`` tracks.

    Parameters
    ----------
    origin_enu, direction_enu : ndarray, shape (3,)
        The ray, local frame (m; the direction need not be unit).
    mean_xy : ndarray, shape (n, 2)
        The tracks' predicted horizontal positions (m).
    cov_xy : ndarray, shape (n, 2, 2)
        Their covariances (m^2, symmetric positive definite).
    z_m : ndarray, shape (n,)
        The tracks' ground heights (m, local up).
    gate_d2 : float
        Squared Mahalanobis gate.
    dz_max_m : float
        Largest height of the ray above or below ``z_m`` where it passes a track (m).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    o = np.asarray(origin_enu, dtype=np.float64)
    d = np.asarray(direction_enu, dtype=np.float64)
    m = np.asarray(mean_xy, dtype=np.float64).reshape(-1, 2) - o[:2]
    c = np.asarray(cov_xy, dtype=np.float64).reshape(-1, 2, 2)
    h = math.hypot(float(d[0]), float(d[1]))
    # inverse of each 2x2 covariance, in closed form
    a, b, cc, e = c[:, 0, 0], c[:, 0, 1], c[:, 1, 0], c[:, 1, 1]
    det = a * e - b * cc
    ok = det > 0
    det = np.where(ok, det, 1.0)
    w00, w01, w10, w11 = e / det, -b / det, -cc / det, a / det
    if h < 1e-9:  # straight down: the ray's ground track is the camera's foot point
        s = np.zeros(len(m))
        ux = uy = 0.0
    else:
        ux, uy = float(d[0]) / h, float(d[1]) / h
        wu0, wu1 = w00 * ux + w01 * uy, w10 * ux + w11 * uy
        uwu = ux * wu0 + uy * wu1
        s = np.maximum(0.0, (m[:, 0] * wu0 + m[:, 1] * wu1) / np.where(uwu > 0, uwu, 1.0))
    rx, ry = s * ux - m[:, 0], s * uy - m[:, 1]
    d2 = rx * (w00 * rx + w01 * ry) + ry * (w10 * rx + w11 * ry)
    z_ray = float(o[2]) + (s * float(d[2]) / h if h >= 1e-9 else 0.0)
    return ok & (d2 <= gate_d2) & (np.abs(z_ray - np.asarray(z_m, dtype=np.float64)) <= dz_max_m)
