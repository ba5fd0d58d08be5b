"""The terrain surface: bilinear interpolation of cell-centre values.

One function, shared by :meth:`Dem.sample`, hole filling and the reference ray caster, so
the surface that is sampled is exactly the surface that rays hit. Small calls run a numba
loop (``core.terrain._surface_kernels``), large ones :func:`bilinear_sample_reference`, its numpy
twin: the same arithmetic in the same order, so the two agree bit for bit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["KERNEL_MAX_POINTS", "bilinear_sample", "bilinear_sample_reference"]

#: Calls with more points take the numpy form (the same bits): its per-call overhead no
#: longer matters there, and the sample site's build (hole filling, rendering: hundreds of
#: thousands of points) then never compiles the kernel on a cold start's critical path.
KERNEL_MAX_POINTS = 4096


def bilinear_sample(values: np.ndarray, gx: ArrayLike, gy: ArrayLike) -> np.ndarray:
    """Bilinear interpolation of a grid of cell-centre values.

    Parameters
    ----------
    values : ndarray, shape (nrows, ncols)
        Cell-centre values; NaN marks nodata.
    gx, gy : array_like
        Fractional column and row indices of cell centres (see ``core.terrain.grid``).

    Returns
    -------
    ndarray, float64, broadcast shape of ``gx`` and ``gy``
        NaN outside ``[0, ncols-1] x [0, nrows-1]`` or where any of the four
        surrounding centres is NaN.
    """
    values = np.asarray(values)
    if not (
        type(gx) is np.ndarray
        and type(gy) is np.ndarray
        and gx.dtype == gy.dtype == np.float64
        and gx.shape == gy.shape
    ):  # float64 arrays of one shape (the usual call) are already what this makes
        gx, gy = np.broadcast_arrays(
            np.asarray(gx, dtype=np.float64), np.asarray(gy, dtype=np.float64)
        )
    if gx.size > KERNEL_MAX_POINTS:
        return bilinear_sample_reference(values, gx, gy)
    from ._surface_kernels import bilinear_kernel  # numba loads on first use

    out = np.empty(gx.shape)
    if out.size:
        bilinear_kernel(
            values,
            np.ascontiguousarray(gx).reshape(-1),
            np.ascontiguousarray(gy).reshape(-1),
            out.reshape(-1),
        )
    return out


def bilinear_sample_reference(values: np.ndarray, gx: ArrayLike, gy: ArrayLike) -> np.ndarray:
    """Numpy twin of :func:`bilinear_sample` (its kernel's oracle): same parameters, same bits."""
    gx, gy = np.broadcast_arrays(np.asarray(gx, dtype=np.float64), np.asarray(gy, dtype=np.float64))
    nrows, ncols = values.shape
    out = np.full(gx.shape, np.nan)
    inside = (gx >= 0) & (gx <= ncols - 1) & (gy >= 0) & (gy <= nrows - 1)
    if not inside.any():
        return out
    x = gx[inside]
    y = gy[inside]
    # The last row/column belong to the patch before them so that c+1 stays in range.
    c = np.minimum(np.floor(x).astype(np.int64), max(ncols - 2, 0))
    r = np.minimum(np.floor(y).astype(np.int64), max(nrows - 2, 0))
    s = x - c
    t = y - r
    c1 = np.minimum(c + 1, ncols - 1)
    r1 = np.minimum(r + 1, nrows - 1)
    # Gather, then widen: widening the whole grid first would copy it on every call.
    z00 = values[r, c].astype(np.float64)
    z01 = values[r, c1].astype(np.float64)
    z10 = values[r1, c].astype(np.float64)
    z11 = values[r1, c1].astype(np.float64)
    out[inside] = z00 * (1 - s) * (1 - t) + z01 * s * (1 - t) + z10 * (1 - s) * t + z11 * s * t
    return out
