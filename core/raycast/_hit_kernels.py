"""numba kernels that turn first-pass hit ranges into CSR hits and points (arrays only).

Inputs are laid out by ``core.raycast.cast``; unit directions are worked out a block of
rays at a time in the same lanes the angular set-up reads (:func:`load_direction_lanes`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._walk_kernels import BLOCK, SCRATCH_ROWS

__all__ = ["gather_hits_kernel", "hit_points_kernel", "load_direction_lanes"]


@njit(cache=True, inline="always")
def load_direction_lanes(directions, q0, q1, lanes):  # pragma: no cover - numba
    """Copy the directions of rays ``q0:q1`` into a block's lanes.

    ``dx, dy, dz`` of the block's ray ``j`` go to ``j``, ``SCRATCH_ROWS + j`` and
    ``2 * SCRATCH_ROWS + j``: the layout the vectorised block loops read.
    """
    R = SCRATCH_ROWS
    for i in range(q0, q1):
        lanes[i - q0] = directions[i, 0]
        lanes[R + i - q0] = directions[i, 1]
        lanes[2 * R + i - q0] = directions[i, 2]


@njit(cache=True, error_model="numpy", inline="always")
def _unit_lanes(lanes):  # pragma: no cover - numba
    """Unit directions of a block's rays, in place, as one vectorised loop.

    ``lanes`` holds ``dx, dy, dz`` of ``BLOCK`` rays at offsets 0, ``SCRATCH_ROWS`` and
    ``2 * SCRATCH_ROWS`` (lanes past the block's end: any values, not read); each becomes
    ``d / |d|`` with the scalar arithmetic, to the bit, 8 rays per division on AVX-512.
    """
    R = SCRATCH_ROWS
    for j in range(BLOCK):
        dx = lanes[j]
        dy = lanes[R + j]
        dz = lanes[2 * R + j]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        lanes[j] = dx / norm
        lanes[R + j] = dy / norm
        lanes[2 * R + j] = dz / norm


@njit(parallel=True, cache=True, error_model="numpy")
def gather_hits_kernel(
    buf, counts, offsets, origins, directions, range_out, points
):  # pragma: no cover - numba
    """Copy the hits of rays whose count fits ``buf`` into their CSR slots, with points.

    ``points[j] = origin + range_out[j] * unit direction``; rays with more hits than
    ``buf`` holds are left to :func:`cast_all_refill_kernel` and :func:`hit_points_kernel`.
    The unit directions are worked out a block of rays at a time (:func:`_unit_lanes`).
    """
    cap = buf.shape[1]
    n = counts.shape[0]
    R = SCRATCH_ROWS
    for blk in prange((n + BLOCK - 1) // BLOCK):
        lanes = np.empty(3 * R, np.float64)
        q0 = blk * BLOCK
        q1 = min(n, q0 + BLOCK)
        load_direction_lanes(directions, q0, q1, lanes)
        _unit_lanes(lanes)
        for i in range(q0, q1):
            c = counts[i]
            if c == 0 or c > cap:
                continue
            ux = lanes[i - q0]
            uy = lanes[R + i - q0]
            uz = lanes[2 * R + i - q0]
            lo = offsets[i]
            for j in range(c):
                t = buf[i, j]
                range_out[lo + j] = t
                points[lo + j, 0] = origins[i, 0] + t * ux
                points[lo + j, 1] = origins[i, 1] + t * uy
                points[lo + j, 2] = origins[i, 2] + t * uz


@njit(parallel=True, cache=True, error_model="numpy")
def hit_points_kernel(origins, directions, rays, offsets, range_m, points):  # pragma: no cover
    """``points[j] = origin + range_m[j] * unit direction`` for the hits of ``rays`` (CSR)."""
    for q in prange(rays.shape[0]):
        i = rays[q]
        lo = offsets[i]
        hi = offsets[i + 1]
        dx = directions[i, 0]
        dy = directions[i, 1]
        dz = directions[i, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        for j in range(lo, hi):
            t = range_m[j]
            points[j, 0] = origins[i, 0] + t * (dx / norm)
            points[j, 1] = origins[i, 1] + t * (dy / norm)
            points[j, 2] = origins[i, 2] + t * (dz / norm)
