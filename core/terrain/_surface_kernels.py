"""numba kernel of the terrain surface (:func:`core.terrain.surface.bilinear_sample`).

The same arithmetic, in the same order, as the numpy form in ``core.terrain.surface`` (kept there
as ``bilinear_sample_reference``), so both give the same bits. One loop over the points
instead of some twenty whole-array numpy steps: most callers sample a handful of points
(a batch's hits, a road crossing, a gradient's four offsets), where numpy's per-call
overhead was nearly all the time.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["bilinear_kernel"]


@njit(cache=True, error_model="numpy")
def bilinear_kernel(values, gx, gy, out):  # pragma: no cover - numba
    """Bilinear interpolation of ``values`` (2-D) at ``(gx[i], gy[i])`` into ``out[i]``.

    ``gx``, ``gy`` and ``out`` are 1-D float64 of one length. NaN outside the hull of
    cell centres or where a surrounding centre is NaN (the NaN propagates).
    """
    nrows, ncols = values.shape
    c_last = max(ncols - 2, 0)
    r_last = max(nrows - 2, 0)
    for i in range(gx.shape[0]):
        x = gx[i]
        y = gy[i]
        if not (x >= 0 and x <= ncols - 1 and y >= 0 and y <= nrows - 1):
            out[i] = math.nan
            continue
        # The last row/column belong to the patch before them so that c+1 stays in range.
        c = min(int(math.floor(x)), c_last)
        r = min(int(math.floor(y)), r_last)
        s = x - c
        t = y - r
        c1 = min(c + 1, ncols - 1)
        r1 = min(r + 1, nrows - 1)
        z00 = float(values[r, c])
        z01 = float(values[r, c1])
        z10 = float(values[r1, c])
        z11 = float(values[r1, c1])
        out[i] = z00 * (1 - s) * (1 - t) + z01 * s * (1 - t) + z10 * (1 - s) * t + z11 * s * t
