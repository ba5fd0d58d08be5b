"""numba kernel of the lens undistortion (arrays only; see ``core.camera.lens``).

Point-by-point twin of ``core.camera.lens.undistort_normalized``: damped Newton on the
distortion's 2x2 Jacobian, with the same steps and tolerances.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["_MAX_HALVINGS", "_MAX_NEWTON_ITER", "_undistort_kernel", "_undistort_point"]

_MAX_NEWTON_ITER = 60
_MAX_HALVINGS = 40


@numba.njit(cache=True, nogil=True)
def _undistort_point(
    tx: float,
    ty: float,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float,
    r2_max: float,
) -> tuple[float, float]:  # pragma: no cover - compiled
    # One point of undistort_normalized (same steps, same tolerances); NaN when no
    # preimage inside the fold radius solves it. Shared by the per-lens kernel here and
    # the per-point-lens kernel of core.geolocation._posed_kernels.
    if not (math.isfinite(tx) and math.isfinite(ty)):
        return np.nan, np.nan
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
        return x, y
    return np.nan, np.nan


@numba.njit(cache=True, nogil=True)
def _undistort_kernel(
    xd: np.ndarray,
    yd: np.ndarray,
    k1: float,
    k2: float,
    p1: float,
    p2: float,
    k3: float,
    k4: float,
    r2_max: float,
    out_x: np.ndarray,
    out_y: np.ndarray,
) -> None:  # pragma: no cover - compiled
    # Point-by-point twin of undistort_normalized (same steps, same tolerances).
    for i in range(xd.size):
        out_x[i], out_y[i] = _undistort_point(xd[i], yd[i], k1, k2, p1, p2, k3, k4, r2_max)
