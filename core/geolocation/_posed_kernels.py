"""numba kernel: the lens undistortion with a lens per point (arrays only).

``core.camera._lens_kernels._undistort_kernel`` with the six coefficients and the fold
radius read per point (a zoom that changes from detection to detection); its reference
twin is that kernel (through ``Intrinsics.undistort``) run point by point, which
``tests/core/geolocation/test_posed_zoom.py`` compares it with.
"""

from __future__ import annotations

import numba
import numpy as np

from ..camera._lens_kernels import _undistort_point

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
        out_x[i], out_y[i] = _undistort_point(xd[i], yd[i], k1, k2, p1, p2, k3, k4, r2_max_px[i])
