"""numba kernel that builds the DEM's min/max pyramid (arrays only; see ``core.raycast.pyramid``).

The Python API and the numpy twin live in ``core.raycast.pyramid``; this module holds only
the parallel builder it calls.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["build_pyramid_kernel"]


@njit(parallel=True, cache=True)
def build_pyramid_kernel(elev, nodes, offsets, shapes):  # pragma: no cover - numba
    """Fill ``nodes`` (all levels) from ``elev``; return ``(z_min, z_max)`` of finite cells."""
    nrows, ncols = elev.shape
    rmin = np.empty(nrows, np.float64)
    rmax = np.empty(nrows, np.float64)
    for r in prange(nrows):
        lo = np.inf
        hi = -np.inf
        for c in range(ncols):
            v = elev[r, c]
            if v == v:
                lo = min(lo, v)
                hi = max(hi, v)
        rmin[r] = lo
        rmax[r] = hi
    z_min = rmin.min()
    z_max = rmax.max()

    # First stored level: blocks of 2 x 2 patches = 3 x 3 cells (clipped at the edge).
    # A NaN anywhere in the block's cells belongs to a patch of the block: a hole.
    br = shapes[0, 0]
    bc = shapes[0, 1]
    for i in prange(br):
        base = offsets[0] + i * bc
        r1 = min(2 * i + 2, nrows - 1)
        for j in range(bc):
            c1 = min(2 * j + 2, ncols - 1)
            lo = np.inf
            hi = -np.inf
            hole = False
            for r in range(2 * i, r1 + 1):
                for c in range(2 * j, c1 + 1):
                    v = elev[r, c]
                    if v != v:
                        hole = True
                    else:
                        lo = min(lo, v)
                        hi = max(hi, v)
            if hole:
                nodes[base + j, 0] = np.inf
                nodes[base + j, 1] = -np.inf
            else:
                nodes[base + j, 0] = hi
                nodes[base + j, 1] = lo

    for k in range(1, shapes.shape[0]):
        rows = shapes[k, 0]
        cols = shapes[k, 1]
        crows = shapes[k - 1, 0]
        ccols = shapes[k - 1, 1]
        coff = offsets[k - 1]
        for i in prange(rows):
            base = offsets[k] + i * cols
            i0 = 2 * i
            i1 = min(2 * i + 1, crows - 1)
            for j in range(cols):
                j0 = 2 * j
                j1 = min(2 * j + 1, ccols - 1)
                n00 = coff + i0 * ccols + j0
                n01 = coff + i0 * ccols + j1
                n10 = coff + i1 * ccols + j0
                n11 = coff + i1 * ccols + j1
                nodes[base + j, 0] = max(
                    max(nodes[n00, 0], nodes[n01, 0]), max(nodes[n10, 0], nodes[n11, 0])
                )
                nodes[base + j, 1] = min(
                    min(nodes[n00, 1], nodes[n01, 1]), min(nodes[n10, 1], nodes[n11, 1])
                )
    return z_min, z_max
