"""First-order uncertainty of a ray-terrain hit.

A hit is the root of ``f(lam) = o_z + lam d_z - S(o_xy + lam d_xy)``, where ``S`` is the
terrain surface. Perturbing the surface by ``dS`` moves the root by ``dS / f'``; turning
the ray by a small angle ``dth`` towards a unit direction ``e`` perpendicular to it moves
the point at range ``lam`` by ``lam e dth`` and the root by
``-lam dth (e_z - g . e_xy) / f'``, where ``f' = d_z - g . d_xy`` and ``g`` is the surface
gradient. These linearised displacements are summed as independent 1-sigma
contributions into a horizontal covariance. The result grows without bound as the ray
grazes the terrain (``f' -> 0``), which is exactly when a small error in the pointing
becomes a large error on the ground.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hit_covariance", "hit_covariances"]


def hit_covariance(
    direction_enu: np.ndarray,
    range_m: np.ndarray,
    gradient: np.ndarray,
    perturb_axes_enu: np.ndarray,
    perturb_sigmas_rad: np.ndarray,
    sigma_z_m: np.ndarray,
) -> np.ndarray:
    """Horizontal 2x2 covariance (m^2) of hits along one ray.

    Parameters
    ----------
    direction_enu : ndarray, shape (3,)
        Unit ray direction, site frame.
    range_m : ndarray, shape (k,)
        Range of each hit along the ray (m).
    gradient : ndarray, shape (k, 2)
        Terrain slope ``(dz/dx, dz/dy)`` at each hit.
    perturb_axes_enu : ndarray, shape (a, 3)
        Unit directions, perpendicular to the ray, towards which the pointing may err
        (the ray ``d`` tips to ``d + dth e``; for pixel noise, the directions in which the
        ray moves as the pixel's column and row change).
    perturb_sigmas_rad : ndarray, shape (a,)
        1-sigma angular error along each axis (rad).
    sigma_z_m : ndarray, shape (k,)
        1-sigma vertical error of the terrain at each hit (m).

    Returns
    -------
    ndarray, shape (k, 2, 2)
        Covariance of the hit's east/north position.
    """
    d = np.asarray(direction_enu, dtype=np.float64)
    lam = np.asarray(range_m, dtype=np.float64)
    g = np.asarray(gradient, dtype=np.float64).reshape(-1, 2)
    fprime = d[2] - g @ d[:2]  # (k,), negative at a downward crossing
    fprime = np.where(np.abs(fprime) < 1e-9, -1e-9, fprime)
    cov = np.zeros((lam.size, 2, 2))
    # Terrain height error.
    disp = (np.asarray(sigma_z_m, dtype=np.float64) / fprime)[:, None] * d[None, :2]
    cov += disp[:, :, None] * disp[:, None, :]
    for e, sig in zip(
        np.asarray(perturb_axes_enu, dtype=np.float64),
        np.asarray(perturb_sigmas_rad, dtype=np.float64),
        strict=True,
    ):
        dlam = -lam * sig * (e[2] - g @ e[:2]) / fprime
        disp = lam[:, None] * sig * e[None, :2] + dlam[:, None] * d[None, :2]
        cov += disp[:, :, None] * disp[:, None, :]
    return cov


def hit_covariances(
    direction_enu: np.ndarray,
    range_m: np.ndarray,
    gradient: np.ndarray,
    perturb_axes_enu: np.ndarray,
    perturb_sigmas_rad: np.ndarray,
    sigma_z_m: np.ndarray,
) -> np.ndarray:
    """Horizontal 2x2 covariances (m^2) of hits on many rays at once.

    The same model as :func:`hit_covariance`, with every input given per hit (each hit
    carries its own ray), so the hits of a whole batch of rays take one call.

    Parameters
    ----------
    direction_enu : ndarray, shape (m, 3)
        Unit direction of each hit's ray, site frame.
    range_m : ndarray, shape (m,)
        Range of each hit along its ray (m).
    gradient : ndarray, shape (m, 2)
        Terrain slope ``(dz/dx, dz/dy)`` at each hit.
    perturb_axes_enu : ndarray, shape (m, a, 3)
        Unit directions, perpendicular to each hit's ray, towards which it may err.
    perturb_sigmas_rad : ndarray, shape (m, a)
        1-sigma angular error along each axis (rad).
    sigma_z_m : ndarray, shape (m,)
        1-sigma vertical error of the terrain at each hit (m).

    Returns
    -------
    ndarray, shape (m, 2, 2)
        Covariance of each hit's east/north position.
    """
    d = np.asarray(direction_enu, dtype=np.float64).reshape(-1, 3)
    lam = np.asarray(range_m, dtype=np.float64).reshape(-1)
    g = np.asarray(gradient, dtype=np.float64).reshape(-1, 2)
    axes = np.asarray(perturb_axes_enu, dtype=np.float64)
    sigs = np.asarray(perturb_sigmas_rad, dtype=np.float64)
    d_xy = d[:, :2]
    fprime = d[:, 2] - (g[:, 0] * d[:, 0] + g[:, 1] * d[:, 1])
    fprime = np.where(np.abs(fprime) < 1e-9, -1e-9, fprime)
    disp = (np.asarray(sigma_z_m, dtype=np.float64).reshape(-1) / fprime)[:, None] * d_xy
    cov = disp[:, :, None] * disp[:, None, :]
    for j in range(axes.shape[1]):
        e, sig = axes[:, j], sigs[:, j]
        dlam = -lam * sig * (e[:, 2] - (g[:, 0] * e[:, 0] + g[:, 1] * e[:, 1])) / fprime
        disp = (lam * sig)[:, None] * e[:, :2] + dlam[:, None] * d_xy
        cov += disp[:, :, None] * disp[:, None, :]
    return cov
