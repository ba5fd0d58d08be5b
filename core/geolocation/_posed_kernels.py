"""numba kernel: the lens undistortion with a lens per point (arrays only).

``core.camera._lens_kernels._undistort_kernel`` with the six coefficients and the fold
radius read per point (a zoom that changes from detection to detection); its reference
twin is that kernel (through ``Intrinsics.undistort``) run point by point, which
``tests/core/geolocation/test_posed_zoom.py`` compares it with.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..camera._lens_kernels import _MAX_HALVINGS, _MAX_NEWTON_ITER

__all__ = ["undistort_each"]


def undistort_each(
    xd: np.ndarray, yd: np.ndarray, coeffs: np.ndarray, r_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Undistort normalised points, each with its own ``(k1, k2, p1, p2, k3, k4)``.

    Parameters
    ----------
    xd, yd : ndarray, shape (k,)
        Distorted normalised coordinates.
    coeffs : ndarray, shape (k, 6)
    r_max : ndarray, shape (k,)
        Each point's radial fold radius (``inf``: none).

    Returns
    -------
    xn, yn : ndarray, shape (k,)
        NaN where no preimage inside the fold exists.
    """
    xd = np.ascontiguousarray(xd, dtype=np.float64).reshape(-1)
    yd = np.ascontiguousarray(yd, dtype=np.float64).reshape(-1)
    out_x, out_y = np.empty_like(xd), np.empty_like(yd)
    r2 = np.ascontiguousarray(np.asarray(r_max, dtype=np.float64) ** 2)
    _undistort_each_kernel(xd, yd, np.ascontiguousarray(coeffs, dtype=np.float64), r2, out_x, out_y)
    return out_x, out_y


@numba.njit(cache=True, nogil=True)
def _undistort_each_kernel(
    xd: np.ndarray,
    yd: np.ndarray,
    coeffs: np.ndarray,
    r2_max_px: np.ndarray,
    out_x: np.ndarray,
    out_y: np.ndarray,
) -> None:  # pragma: no cover - compiled
    # _undistort_kernel's steps and tolerances, with each point's own coefficients.
    for i in range(xd.size):
        k1, k2, p1, p2, k3, k4 = (
            coeffs[i, 0], coeffs[i, 1], coeffs[i, 2], coeffs[i, 3], coeffs[i, 4], coeffs[i, 5]
        )  # fmt: skip
        r2_max = r2_max_px[i]
        tx, ty = xd[i], yd[i]
        out_x[i] = np.nan
        out_y[i] = np.nan
        if not (math.isfinite(tx) and math.isfinite(ty)):
            continue
        x, y = tx, ty
        r2 = x * x + y * y
        if r2 > 0.81 * r2_max:
            scale = 0.9 * math.sqrt(r2_max / r2)
            x *= scale
            y *= scale
        tol_e = 1e-15 * (1.0 + math.sqrt(tx * tx + ty * ty))
        for _ in range(_MAX_NEWTON_ITER):
            r2 = x * x + y * y
            g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
            ex = x * g + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - tx
            ey = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - ty
            e0 = ex * ex + ey * ey
            if e0 <= tol_e * tol_e:
                break
            dg = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + 4.0 * k4 * r2))
            off = 2.0 * x * y * dg + 2.0 * p1 * x + 2.0 * p2 * y
            a = g + 2.0 * x * x * dg + 2.0 * p1 * y + 6.0 * p2 * x
            d = g + 2.0 * y * y * dg + 6.0 * p1 * y + 2.0 * p2 * x
            det = a * d - off * off
            if det == 0.0:
                break
            dx = (d * ex - off * ey) / det
            dy = (a * ey - off * ex) / det
            step = 1.0
            accepted = False
            xn, yn = x, y
            for _h in range(_MAX_HALVINGS):
                xn = x - step * dx
                yn = y - step * dy
                r2n = xn * xn + yn * yn
                gn = 1.0 + r2n * (k1 + r2n * (k2 + r2n * (k3 + r2n * k4)))
                fx = xn * gn + 2.0 * p1 * xn * yn + p2 * (r2n + 2.0 * xn * xn) - tx
                fy = yn * gn + p1 * (r2n + 2.0 * yn * yn) + 2.0 * p2 * xn * yn - ty
                if r2n < r2_max and fx * fx + fy * fy <= e0:
                    accepted = True
                    break
                step *= 0.5
            if not accepted:
                break
            moved = math.sqrt((xn - x) ** 2 + (yn - y) ** 2)
            done = moved <= 4e-16 * (1.0 + math.sqrt(x * x + y * y))
            x, y = xn, yn
            if done:
                break
        r2 = x * x + y * y
        g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
        ex = x * g + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - tx
        ey = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - ty
        tol_r = 1e-12 * (1.0 + math.sqrt(tx * tx + ty * ty))
        if math.sqrt(ex * ex + ey * ey) <= tol_r and r2 < r2_max:
            out_x[i] = x
            out_y[i] = y
