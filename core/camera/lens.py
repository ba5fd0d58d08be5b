"""OpenCV's lens-distortion model on normalised image coordinates: distort, undistort.

OpenCV's radial (``k1, k2, k3``) and tangential (``p1, p2``) distortion of
the ideal normalised coordinates ``(xn, yn) = (x/z, y/z)``, with one more radial term,
``k4`` on ``r^8`` (the polynomial Brown model of Agisoft Metashape and weitsicht; **not**
OpenCV's rational ``k4``, which divides; 0 gives OpenCV's five-coefficient model)::

    r2 = xn^2 + yn^2,   g = 1 + k1 r2 + k2 r2^2 + k3 r2^3 + k4 r2^4
    xd = xn g + 2 p1 xn yn + p2 (r2 + 2 xn^2)
    yd = yn g + p1 (r2 + 2 yn^2) + 2 p2 xn yn
    u = fx xd + cx,     v = fy yd + cy

Undistortion inverts this map by damped Newton iteration on its 2x2 Jacobian (OpenCV's
plain fixed-point loop stalls or diverges at the corners of strongly distorted lenses).
A polynomial radial model folds back on itself beyond the radius where
``d(r g)/dr = 0``; ``core.camera.pinhole.Intrinsics`` refuses coefficients that fold
inside the image, and the projection kernels return NaN for rays beyond the fold, which a
folded model would otherwise map back *into* the image.

The functions are permissive array kernels (no input checks, NaN where there is no
answer); ``core.camera.pinhole.Intrinsics`` validates. Undistortion has a numba kernel
(:func:`undistort_normalized_nb`, in ``core.camera._lens_kernels``, used by
``Intrinsics.undistort``) and a plain-numpy twin (:func:`undistort_normalized`, used by the
construction check and the tests).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._lens_kernels import _MAX_HALVINGS, _MAX_NEWTON_ITER, _undistort_kernel

__all__ = [
    "distort_normalized",
    "distortion_jacobian",
    "radial_fold_radius",
    "undistort_normalized",
    "undistort_normalized_nb",
]

# Normalised radius (tan of the off-axis angle) beyond which folds are not looked for:
# 1e4 is 89.994 degrees off the optical axis.
_R_FOLD_MAX = 1e4


def distort_normalized(
    xn: np.ndarray,
    yn: np.ndarray,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Apply OpenCV distortion to ideal normalised coordinates.

    Parameters
    ----------
    xn, yn : ndarray
        Ideal (undistorted) normalised image coordinates ``x/z, y/z`` (camera frame).
    k1, k2, p1, p2, k3 : float
        OpenCV distortion coefficients.
    k4 : float
        Radial coefficient of ``r^8`` (polynomial, not OpenCV's rational ``k4``).

    Returns
    -------
    xd, yd : ndarray
        Distorted normalised coordinates, same shape as the broadcast inputs.
    """
    r2 = xn * xn + yn * yn
    g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
    xy = xn * yn
    xd = xn * g + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xn * xn)
    yd = yn * g + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xy
    return xd, yd


def distortion_jacobian(
    xn: np.ndarray,
    yn: np.ndarray,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Jacobian of :func:`distort_normalized`.

    Returns
    -------
    dxd_dx, dxd_dy, dyd_dx, dyd_dy : ndarray
        Partial derivatives (the two off-diagonal terms are equal for this model).
    """
    r2 = xn * xn + yn * yn
    g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
    dg = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + 4.0 * k4 * r2))  # dg / d(r2)
    off = 2.0 * xn * yn * dg + 2.0 * p1 * xn + 2.0 * p2 * yn
    a = g + 2.0 * xn * xn * dg + 2.0 * p1 * yn + 6.0 * p2 * xn
    d = g + 2.0 * yn * yn * dg + 6.0 * p1 * yn + 2.0 * p2 * xn
    return a, off, off, d


def radial_fold_radius(k1: float, k2: float, k3: float, k4: float = 0.0) -> float:
    """Smallest undistorted radius where the radial map ``r * g(r^2)`` stops increasing.

    Parameters
    ----------
    k1, k2, k3, k4 : float
        Radial coefficients (``k4`` on ``r^8``).

    Returns
    -------
    float
        The first positive root of
        ``d(r g)/dr = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 + 9 k4 r^8``
        (normalised units), or ``inf`` if the map is monotonic for all ``r >= 0``.
    """
    # Coefficients in s = r^2, highest power first. Leading terms that stay below 1e-12
    # for every r <= _R_FOLD_MAX cannot fold the model where it matters; dropping them
    # also keeps the companion matrix finite (a denormal k3 would overflow it).
    poly = [9.0 * k4, 7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]
    while len(poly) > 1 and abs(poly[0]) * _R_FOLD_MAX ** (2 * (len(poly) - 1)) < 1e-12:
        poly.pop(0)
    if len(poly) <= 1:
        return math.inf
    roots = np.roots(poly)
    # A double root (the derivative just touching zero) may come back as a complex pair
    # with a round-off imaginary part; count it as a fold, conservatively.
    tol = 1e-7 * np.maximum(1.0, np.abs(roots))
    s = roots.real[(np.abs(roots.imag) <= tol) & (roots.real > 0.0)]
    return float(math.sqrt(s.min())) if s.size else math.inf


def undistort_normalized(
    xd: ArrayLike,
    yd: ArrayLike,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float = 0.0,
    r_max: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort_normalized` by damped Newton iteration.

    Each step solves the 2x2 Jacobian system; a step is halved while it would leave the
    disc ``r < r_max`` (the radial fold) or increase the residual, which keeps the
    iteration on the invertible branch even from a poor start.

    Parameters
    ----------
    xd, yd : array_like
        Distorted normalised coordinates (broadcast together).
    k1, k2, p1, p2, k3 : float
        OpenCV distortion coefficients.
    k4 : float
        Radial coefficient of ``r^8`` (see the module notes).
    r_max : float
        Undistorted radius the solution must stay within (see :func:`radial_fold_radius`).

    Returns
    -------
    xn, yn : ndarray, float64
        Ideal normalised coordinates, broadcast shape; NaN where the input is not finite
        or has no preimage inside ``r_max`` (the iteration did not converge).
    """
    xd, yd = np.broadcast_arrays(np.asarray(xd, dtype=np.float64), np.asarray(yd, dtype=np.float64))
    shape = xd.shape
    xd = xd.ravel().copy()
    yd = yd.ravel().copy()
    if k1 == 0.0 and k2 == 0.0 and k3 == 0.0 and k4 == 0.0 and p1 == 0.0 and p2 == 0.0:
        return xd.reshape(shape), yd.reshape(shape)
    coeffs = (k1, k2, p1, p2, k3, k4)
    r2_max = r_max * r_max
    x = xd.copy()
    y = yd.copy()
    # Start inside the fold so that the first Jacobian is on the right branch.
    r2 = x * x + y * y
    over = r2 > 0.81 * r2_max
    if over.any():
        scale = 0.9 * r_max / np.sqrt(r2[over])
        x[over] *= scale
        y[over] *= scale
    ok = np.isfinite(xd) & np.isfinite(yd)
    active = np.flatnonzero(ok)
    for _ in range(_MAX_NEWTON_ITER):
        if active.size == 0:
            break
        xa, ya, ta, tb = x[active], y[active], xd[active], yd[active]
        fx, fy = distort_normalized(xa, ya, *coeffs)
        ex, ey = fx - ta, fy - tb
        e0 = ex * ex + ey * ey
        # Already at round-off level: another step could only shuffle the last bits.
        conv = e0 <= (1e-15 * (1.0 + np.hypot(ta, tb))) ** 2
        if conv.any():
            keep = ~conv
            active = active[keep]
            xa, ya, ta, tb, ex, ey, e0 = (w[keep] for w in (xa, ya, ta, tb, ex, ey, e0))
            if active.size == 0:
                break
        a, b, c, d = distortion_jacobian(xa, ya, *coeffs)
        det = a * d - b * c
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (d * ex - b * ey) / det
            dy = (a * ey - c * ex) / det
        step = np.ones_like(xa)
        xn, yn = xa - dx, ya - dy
        for _ in range(_MAX_HALVINGS):
            fx2, fy2 = distort_normalized(xn, yn, *coeffs)
            e1 = (fx2 - ta) ** 2 + (fy2 - tb) ** 2
            bad = ~((xn * xn + yn * yn < r2_max) & (e1 <= e0))
            if not bad.any():
                break
            step = np.where(bad, 0.5 * step, step)
            xn = np.where(bad, xa - step * dx, xn)
            yn = np.where(bad, ya - step * dy, yn)
        moved = np.hypot(xn - xa, yn - ya)
        accept = np.isfinite(xn) & np.isfinite(yn) & ~bad
        x[active] = np.where(accept, xn, xa)
        y[active] = np.where(accept, yn, ya)
        # A point is done once Newton's correction is at round-off level, or when no
        # descent step exists any more (it then either sits on the root or has none).
        done = ~accept | (moved <= 4e-16 * (1.0 + np.hypot(xa, ya)))
        active = active[~done]
    fx, fy = distort_normalized(x, y, *coeffs)
    resid = np.hypot(fx - xd, fy - yd)
    good = ok & (resid <= 1e-12 * (1.0 + np.hypot(xd, yd))) & (x * x + y * y < r2_max)
    x[~good] = np.nan
    y[~good] = np.nan
    return x.reshape(shape), y.reshape(shape)


def undistort_normalized_nb(
    xd: ArrayLike,
    yd: ArrayLike,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float = 0.0,
    r_max: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled twin of :func:`undistort_normalized` (same arguments and results).

    Used by :meth:`Intrinsics.undistort`: about twenty times faster on full-frame pixel
    grids. Compiled (and cached on disk) at first call.
    """
    xd, yd = np.broadcast_arrays(np.asarray(xd, dtype=np.float64), np.asarray(yd, dtype=np.float64))
    shape = xd.shape
    xd = np.ascontiguousarray(xd.ravel())
    yd = np.ascontiguousarray(yd.ravel())
    if k1 == 0.0 and k2 == 0.0 and k3 == 0.0 and k4 == 0.0 and p1 == 0.0 and p2 == 0.0:
        return xd.copy().reshape(shape), yd.copy().reshape(shape)
    out_x = np.empty_like(xd)
    out_y = np.empty_like(yd)
    _undistort_kernel(
        xd,
        yd,
        float(k1),
        float(k2),
        float(p1),
        float(p2),
        float(k3),
        float(k4),
        float(r_max) ** 2,
        out_x,
        out_y,
    )
    return out_x.reshape(shape), out_y.reshape(shape)
