"""numba kernels over a batch of rays before casting: checks and locality order (arrays only).

:func:`check_rays_kernel` finds the first malformed ray for ``core.raycast.cast``'s error
messages; :func:`ray_order_kernel` sorts large incoherent batches by origin tile and
direction.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["ORDER_TILE_SHIFT", "check_rays_kernel", "ray_order_kernel"]

ORDER_TILE_SHIFT = 6


@njit(parallel=True, cache=True)
def ray_order_kernel(
    origins, directions, max_range, x_min, y_max, cell, nrows, ncols, nthreads, o_out, d_out, r_out
):  # pragma: no cover - numba
    """A cast order for incoherent rays, grouped by origin tile and direction octant.

    Rays that start in the same tile of ``2**ORDER_TILE_SHIFT`` cells and head into
    the same octant walk mostly the same pyramid nodes and grid rows, so casting them
    one after the other keeps those in cache (random rays over a large DEM otherwise
    spend most of their time waiting on memory). A counting sort, stable within a
    group, that also copies the rays into that order: ``o_out[q] = origins[order[q]]``
    and the same for ``directions`` into ``d_out`` and ``max_range`` into ``r_out``
    (written group by group as the input is read in order, which the caches absorb far
    better than reads through the permutation). Each of ``nthreads`` threads sorts a
    contiguous share of the rays into its own slots of each group, so the order is the
    same for any thread count. Returns ``order``, int64 ``(n,)``.
    """
    n = origins.shape[0]
    sh = ORDER_TILE_SHIFT
    ntx = ((ncols - 1) >> sh) + 1
    nty = ((nrows - 1) >> sh) + 1
    n_keys = ntx * nty * 8
    gxmax = float(ncols - 1)
    gymax = float(nrows - 1)
    keys = np.empty(n, np.int32)
    # Row t of ``slots``: thread t's count per group, then its first slot in each group.
    slots = np.zeros((nthreads, n_keys), np.int64)
    for t in prange(nthreads):
        for i in range(t * n // nthreads, (t + 1) * n // nthreads):
            gx = min(max((origins[i, 0] - x_min) / cell, 0.0), gxmax)
            gy = min(max((y_max - origins[i, 1]) / cell, 0.0), gymax)
            dx = directions[i, 0]
            dy = directions[i, 1]
            octant = (
                (4 if dx < 0.0 else 0) + (2 if dy < 0.0 else 0) + (1 if abs(dx) < abs(dy) else 0)
            )
            k = (((int(gy) >> sh) * ntx + (int(gx) >> sh)) << 3) + octant
            keys[i] = k
            slots[t, k] += 1
    acc = 0
    for k in range(n_keys):
        for t in range(nthreads):
            c = slots[t, k]
            slots[t, k] = acc
            acc += c
    order = np.empty(n, np.int64)
    for t in prange(nthreads):
        for i in range(t * n // nthreads, (t + 1) * n // nthreads):
            k = keys[i]
            q = slots[t, k]
            slots[t, k] = q + 1
            order[q] = i
            o_out[q, 0] = origins[i, 0]
            o_out[q, 1] = origins[i, 1]
            o_out[q, 2] = origins[i, 2]
            d_out[q, 0] = directions[i, 0]
            d_out[q, 1] = directions[i, 1]
            d_out[q, 2] = directions[i, 2]
            r_out[q] = max_range[i]
    return order


@njit(cache=True, inline="always")
def _ray_problem(origins, directions, max_range, i):  # pragma: no cover - numba
    """:func:`check_rays_kernel`'s code for ray ``i`` (0 when it is fine)."""
    ox = origins[i, 0]
    oy = origins[i, 1]
    oz = origins[i, 2]
    if not (math.isfinite(ox) and math.isfinite(oy) and math.isfinite(oz)):
        return 1
    dx = directions[i, 0]
    dy = directions[i, 1]
    dz = directions[i, 2]
    if not (math.isfinite(dx) and math.isfinite(dy) and math.isfinite(dz)):
        return 2
    if not dx * dx + dy * dy + dz * dz > 0.0:
        return 3
    if not max_range[i] >= 0.0:
        return 4
    return 0


@njit(parallel=True, cache=True)
def check_rays_kernel(origins, directions, max_range, nt):  # pragma: no cover - numba
    """First problem in a batch of rays, as ``(code, ray)``; ``(0, -1)`` when none.

    Codes: 1 a non-finite origin, 2 a non-finite direction, 3 a zero direction,
    4 a NaN or negative ``max_range``. One pass: each of ``nt`` contiguous shares (numba's
    thread count) is checked on its own up to its first problem; the earliest share's
    problem is the batch's first.
    """
    n = origins.shape[0]
    ray = np.full(nt, n, np.int64)
    code = np.zeros(nt, np.int64)
    for t in prange(nt):
        for i in range(t * n // nt, (t + 1) * n // nt):
            c = _ray_problem(origins, directions, max_range, i)
            if c != 0:
                ray[t] = i
                code[t] = c
                break
    for t in range(nt):
        if ray[t] < n:
            return code[t], ray[t]
    return 0, -1
