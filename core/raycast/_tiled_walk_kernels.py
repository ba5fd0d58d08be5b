"""The pyramid walk over a tiled DEM, suspended where a tile is missing (numba, arrays only).

The same walk as ``core.raycast._walk_kernels`` (set-up, hierarchical DDA, patch solver),
operation for operation, so the answers are the same to the bit, with the DEM's data in
two places:

- the coarse levels of the min/max pyramid (level ``T = log2(tile)``, one node per *patch
  block* of ``tile x tile`` patches, and above) in one table, always in memory;
- each resident block's cells (with a one-cell halo) and its own levels ``1 .. T-1`` in a
  *slot* of a fixed pool, ``tile_slot[by, bx]`` naming the slot or ``-1``.

Below level ``T`` a node (and a patch) lies inside one block, so the walk reads the slot of
the block it is in. When that block is not resident, the ray's walk state (node, level, the
Amanatides-Woo face ranges, hits so far) is saved and the ray is *suspended*, with the
block it waits for in ``need``; ``core.raycast.tiled_cast`` loads blocks and runs the kernel
again over the suspended rays, which resume exactly where they stopped. The coarse levels
skip whole blocks the ray passes above (or below) without loading them.

Per-ray state rows: ``geo`` = ``(gx0, gy0, kx, ky, uz, t_a, t_end)`` from the set-up,
``fst`` = ``(tmx, tmy, dxl, dyl, t_cur, z_cur, last_t)``, ``ist`` = ``(level, nx, ny, count,
crossed, last_block, visits, misses)``; ``phase`` 0 = not set up, 1 = walking, 2 = done.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._walk_kernels import (
    BELOW_GROUND,
    HIT,
    MISS,
    OUTSIDE,
    UPWARD,
    _solve_patch,
    bilinear,
    climb_step,
    clip_to_hull,
    clip_to_slab,
    face_step,
    keep_root,
)

__all__ = ["NEED", "tiled_cast_kernel"]

#: Set-up status of a ray whose origin block must be loaded first (never returned).
NEED = -1


@njit(cache=True, error_model="numpy", inline="always")
def _node(
    level, nx, ny, T, coarse, coarse_off, lvl_shape, pool_nodes, local_off, slot
):  # pragma: no cover
    """(max, min) of pyramid node ``(ny, nx)`` at ``level >= 1``: coarse table or slot."""
    if level >= T:
        k = coarse_off[level - T] + ny * lvl_shape[level - 1, 1] + nx
        return coarse[k, 0], coarse[k, 1]
    sh = T - level
    m = (1 << sh) - 1
    k = local_off[level - 1] + (ny & m) * (1 << sh) + (nx & m)
    return pool_nodes[slot, k, 0], pool_nodes[slot, k, 1]


@njit(cache=True, error_model="numpy")
def _solve_local(pe, ly, lx, iy, ix, gx0, gy0, kx, ky, uz, t0, z_t0):  # pragma: no cover
    """``_walk_kernels._solve_at`` for patch ``(iy, ix)`` stored at ``pe[ly, lx]``."""
    e00 = np.float64(pe[ly, lx])
    e01 = np.float64(pe[ly, lx + 1])
    e10 = np.float64(pe[ly + 1, lx])
    e11 = np.float64(pe[ly + 1, lx + 1])
    if e00 != e00 or e01 != e01 or e10 != e10 or e11 != e11:
        return np.nan
    return _solve_patch(e00, e01, e10, e11, ix, iy, gx0, gy0, kx, ky, uz, t0, z_t0)


@njit(cache=True, error_model="numpy", inline="always")
def _patch_root(
    pe, ly, lx, holes, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur, zl, zh
):  # pragma: no cover
    """``_walk_kernels.patch_root`` for patch ``(ny, nx)`` stored at ``pe[ly, lx]``.

    The slot's halo holds the row and column before the block, which the grid-line
    neighbours of a hole need.
    """
    e00 = np.float64(pe[ly, lx])
    e01 = np.float64(pe[ly, lx + 1])
    e10 = np.float64(pe[ly + 1, lx])
    e11 = np.float64(pe[ly + 1, lx + 1])
    s = np.nan
    hole = False
    if holes and (e00 != e00 or e01 != e01 or e10 != e10 or e11 != e11):
        hole = True
        on_x = kx == 0.0 and nx > 0 and gx0 == nx
        on_y = ky == 0.0 and ny > 0 and gy0 == ny
        if on_x:
            s = _solve_local(pe, ly, lx - 1, ny, nx - 1, gx0, gy0, kx, ky, uz, t_cur, z_cur)
        if on_y and s != s:
            s = _solve_local(pe, ly - 1, lx, ny - 1, nx, gx0, gy0, kx, ky, uz, t_cur, z_cur)
        if on_x and on_y and s != s:
            s = _solve_local(pe, ly - 1, lx - 1, ny - 1, nx - 1, gx0, gy0, kx, ky, uz, t_cur, z_cur)
    elif zl < max(max(e00, e01), max(e10, e11)) and zh > min(min(e00, e01), min(e10, e11)):
        s = _solve_patch(e00, e01, e10, e11, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur)
    return s, hole


@njit(cache=True, error_model="numpy")
def _prepare(
    nrows, ncols, T, block_max, tile_slot, pool_elev, pool_nodes, local_off, coarse,
    coarse_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
    ox, oy, oz, dx, dy, dz, max_range,
):  # fmt: skip  # pragma: no cover - numba
    """``_walk_kernels._prepare`` on the tiled DEM; status ``NEED`` (block in ``t_a``).

    The below-ground test reads a level-4 node and the patch under the origin; the
    block's coarse max decides first whether that read can matter (an origin at or above
    its block's max is above every node in it), so a block is loaded only when it must be.
    """
    gxmax = ncols - 1.0
    gymax = nrows - 1.0
    gx0 = (ox - x_min) / cell - 0.5
    gy0 = (y_max - oy) / cell - 0.5
    kx, ky, uz, t_lo, t_hi = clip_to_hull(nrows, ncols, gx0, gy0, dx, dy, dz, cell, max_range)
    if not (t_lo <= t_hi):
        return OUTSIDE, gx0, gy0, kx, ky, uz, 0.0, 0.0

    if uz >= 0.0 and oz >= z_max:
        return UPWARD, gx0, gy0, kx, ky, uz, 0.0, 0.0

    if gx0 >= 0.0 and gx0 <= gxmax and gy0 >= 0.0 and gy0 <= gymax:
        ix = min(int(math.floor(gx0)), ncols - 2)
        iy = min(int(math.floor(gy0)), nrows - 2)
        by = iy >> T
        bx = ix >> T
        if oz < block_max[by, bx]:
            slot = tile_slot[by, bx]
            if slot < 0:
                return NEED, gx0, gy0, kx, ky, uz, float(by * block_max.shape[1] + bx), 0.0
            lv = min(4, lvl_shape.shape[0])
            mx, _mn = _node(
                lv,
                ix >> lv,
                iy >> lv,
                T,
                coarse,
                coarse_off,
                lvl_shape,
                pool_nodes,
                local_off,
                slot,
            )
            if oz < mx:
                pe = pool_elev[slot]
                ly = iy - (by << T) + 1
                lx = ix - (bx << T) + 1
                e00 = pe[ly, lx]
                e01 = pe[ly, lx + 1]
                e10 = pe[ly + 1, lx]
                e11 = pe[ly + 1, lx + 1]
                if e00 == e00 and e01 == e01 and e10 == e10 and e11 == e11:
                    if oz < bilinear(e00, e01, e10, e11, gx0 - ix, gy0 - iy):
                        return BELOW_GROUND, gx0, gy0, kx, ky, uz, 0.0, 0.0

    t_lo, t_hi = clip_to_slab(t_lo, t_hi, oz, uz, z_min - margin, z_max + margin)
    if not (t_lo <= t_hi):
        return MISS, gx0, gy0, kx, ky, uz, 0.0, 0.0
    return HIT, gx0, gy0, kx, ky, uz, t_lo, t_hi


@njit(cache=True, error_model="numpy", inline="always")
def _start(nrows, ncols, top, gx0, gy0, oz, kx, ky, uz, t_a, t_end):  # pragma: no cover
    """The walk's first state, as ``_walk_kernels._walk`` sets it up."""
    pcols = ncols - 1
    prows = nrows - 1
    ix0 = min(max(int(math.floor(gx0 + t_a * kx)), 0), pcols - 1)
    iy0 = min(max(int(math.floor(gy0 + t_a * ky)), 0), prows - 1)
    foot = (t_end - t_a) * max(abs(kx), abs(ky))
    level = max(1, min(top, math.frexp(0.25 * foot + 2.0)[1]))
    fx = 1 if kx > 0.0 else 0
    fy = 1 if ky > 0.0 else 0
    ikx = 1.0 / kx if kx != 0.0 else 0.0
    iky = 1.0 / ky if ky != 0.0 else 0.0
    dxl = abs(ikx) * (1 << level)
    dyl = abs(iky) * (1 << level)
    nx = ix0 >> level
    ny = iy0 >> level
    tmx = (((nx + fx) << level) - gx0) * ikx if kx != 0.0 else np.inf
    tmy = (((ny + fy) << level) - gy0) * iky if ky != 0.0 else np.inf
    return level, nx, ny, tmx, tmy, dxl, dyl, t_a, oz + t_a * uz


@njit(cache=True, error_model="numpy")
def _walk(
    i, nrows, ncols, T, tile_slot, pool_elev, pool_nodes, local_off, coarse, coarse_off,
    lvl_shape, holes, margin, z0, geo, fst, ist, stamp, rnd,
    hits, base, cap, max_count, first_only,
):  # fmt: skip  # pragma: no cover - numba
    """Resume ray ``i``'s walk; returns the block it waits for, or ``-1`` when it is done.

    The loop is ``_walk_kernels._walk``'s; only the reads of nodes below level ``T`` and
    of patches go through the ray's current block's slot.
    """
    pcols = ncols - 1
    prows = nrows - 1
    top = lvl_shape.shape[0]
    nbx = tile_slot.shape[1]
    gx0, gy0, kx, ky = geo[i, 0], geo[i, 1], geo[i, 2], geo[i, 3]
    uz, t_a, t_end = geo[i, 4], geo[i, 5], geo[i, 6]
    ix0 = min(max(int(math.floor(gx0 + t_a * kx)), 0), pcols - 1)
    iy0 = min(max(int(math.floor(gy0 + t_a * ky)), 0), prows - 1)
    fx = 1 if kx > 0.0 else 0
    fy = 1 if ky > 0.0 else 0
    sx = 1 if kx > 0.0 else -1
    sy = 1 if ky > 0.0 else -1
    ikx = 1.0 / kx if kx != 0.0 else 0.0
    iky = 1.0 / ky if ky != 0.0 else 0.0
    tmx, tmy, dxl, dyl = fst[i, 0], fst[i, 1], fst[i, 2], fst[i, 3]
    t_cur, z_cur, last_t = fst[i, 4], fst[i, 5], fst[i, 6]
    level, nx, ny, count = ist[i, 0], ist[i, 1], ist[i, 2], ist[i, 3]
    crossed = ist[i, 4] != 0
    last_blk, visits, misses = ist[i, 5], ist[i, 6], ist[i, 7]
    ncl = pcols if level == 0 else lvl_shape[level - 1, 1]
    nrl = prows if level == 0 else lvl_shape[level - 1, 0]
    waiting = -1
    slot = -1
    while True:
        t_exit = max(min(min(tmx, tmy), t_end), t_cur)
        z_exit = z0 + t_exit * uz
        zl = min(z_cur, z_exit) - margin
        zh = max(z_cur, z_exit) + margin
        if level < T:
            sh = T - level
            by = ny >> sh
            bx = nx >> sh
            blk = by * nbx + bx
            slot = tile_slot[by, bx]
            if blk != last_blk:
                last_blk = blk
                visits += 1
                if slot < 0:
                    misses += 1
            if slot < 0:
                waiting = blk
                break
            stamp[slot] = rnd
        if level > 0:
            mx, mn = _node(
                level, nx, ny, T, coarse, coarse_off, lvl_shape, pool_nodes, local_off, slot
            )
            if zl < mx and zh > mn:
                level -= 1
                dxl *= 0.5
                dyl *= 0.5
                if level == 0:
                    ncl = pcols
                    nrl = prows
                else:
                    ncl = lvl_shape[level - 1, 1]
                    nrl = lvl_shape[level - 1, 0]
                if kx != 0.0:
                    t_mid = (((2 * nx + 1) << level) - gx0) * ikx
                    far = t_mid <= t_cur or (fx == 0 and 2 * nx + 1 >= ncl)
                    nx = 2 * nx + (fx if far else 1 - fx)
                    tmx = tmx if far else t_mid
                else:
                    nx = ix0 >> level
                if ky != 0.0:
                    t_mid = (((2 * ny + 1) << level) - gy0) * iky
                    far = t_mid <= t_cur or (fy == 0 and 2 * ny + 1 >= nrl)
                    ny = 2 * ny + (fy if far else 1 - fy)
                    tmy = tmy if far else t_mid
                else:
                    ny = iy0 >> level
                nx = min(nx, ncl - 1)
                ny = min(ny, nrl - 1)
                continue
        else:
            ly = ny - ((ny >> T) << T) + 1
            lx = nx - ((nx >> T) << T) + 1
            s, hole = _patch_root(
                pool_elev[slot], ly, lx, holes, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur, zl, zh
            )
            crossed = crossed or hole
            count, last_t, kept = keep_root(s, t_cur, t_exit, hits, base, cap, count, last_t)
            if kept and (first_only or count > max_count):
                break
        if t_exit >= t_end:
            break
        nx, ny, tmx, tmy, t_cur, bx_ = face_step(nx, ny, sx, sy, tmx, tmy, dxl, dyl)
        if nx < 0 or nx >= ncl or ny < 0 or ny >= nrl:
            break
        z_cur = z_exit
        nx, ny, level, tmx, tmy, dxl, dyl, climbed = climb_step(
            nx, ny, fx, fy, bx_, level, top, tmx, tmy, dxl, dyl
        )
        if climbed:
            ncl = lvl_shape[level - 1, 1]
            nrl = lvl_shape[level - 1, 0]
    fst[i, 0], fst[i, 1], fst[i, 2], fst[i, 3] = tmx, tmy, dxl, dyl
    fst[i, 4], fst[i, 5], fst[i, 6] = t_cur, z_cur, last_t
    ist[i, 0], ist[i, 1], ist[i, 2], ist[i, 3] = level, nx, ny, count
    ist[i, 4] = 1 if crossed else 0
    ist[i, 5], ist[i, 6], ist[i, 7] = last_blk, visits, misses
    return waiting


@njit(parallel=True, cache=True, error_model="numpy")
def tiled_cast_kernel(
    nrows, ncols, T, block_max, tile_slot, pool_elev, pool_nodes, local_off, coarse,
    coarse_off, lvl_shape, holes, x_min, y_max, cell, z_min, z_max, margin,
    origins, directions, max_range, first_only, max_hits, rays, rnd,
    phase, geo, fst, ist, need, stamp, buf, counts, status, crossed, truncated,
):  # fmt: skip  # pragma: no cover - numba
    """Set up or resume every ray of ``rays`` (int64) until it is done or waits for a block.

    ``need[i]`` receives the block (``by * block_cols + bx``) ray ``i`` waits for, or -1.
    ``stamp[slot]`` is set to ``rnd`` for every slot read (for the cache's LRU order).
    Outputs of a finished ray as ``core.raycast._kernels.cast_kernel`` writes them: its
    first ``buf.shape[1]`` hit ranges in ``buf``, ``counts`` (capped at ``max_hits``),
    ``status``, ``crossed``, ``truncated``.
    """
    cap = buf.shape[1]
    hits = buf.reshape(buf.size)
    top = lvl_shape.shape[0]
    for q in prange(rays.shape[0]):
        i = rays[q]
        need[i] = -1
        if phase[i] == 0:
            st, gx0, gy0, kx, ky, uz, t_a, t_end = _prepare(
                nrows, ncols, T, block_max, tile_slot, pool_elev, pool_nodes, local_off,
                coarse, coarse_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
                origins[i, 0], origins[i, 1], origins[i, 2],
                directions[i, 0], directions[i, 1], directions[i, 2], max_range[i],
            )  # fmt: skip
            if st == NEED:
                need[i] = int(t_a)
                continue
            if st != HIT:
                crossed[i] = False
                truncated[i] = False
                counts[i] = 0
                status[i] = st
                phase[i] = 2
                continue
            geo[i, 0], geo[i, 1], geo[i, 2], geo[i, 3] = gx0, gy0, kx, ky
            geo[i, 4], geo[i, 5], geo[i, 6] = uz, t_a, t_end
            level, nx, ny, tmx, tmy, dxl, dyl, t_cur, z_cur = _start(
                nrows, ncols, top, gx0, gy0, origins[i, 2], kx, ky, uz, t_a, t_end
            )
            fst[i, 0], fst[i, 1], fst[i, 2], fst[i, 3] = tmx, tmy, dxl, dyl
            fst[i, 4], fst[i, 5], fst[i, 6] = t_cur, z_cur, -np.inf
            ist[i, 0], ist[i, 1], ist[i, 2], ist[i, 3], ist[i, 4] = level, nx, ny, 0, 0
            phase[i] = 1
        if phase[i] == 1:
            waiting = _walk(
                i, nrows, ncols, T, tile_slot, pool_elev, pool_nodes, local_off, coarse,
                coarse_off, lvl_shape, holes, margin, origins[i, 2], geo, fst, ist, stamp, rnd,
                hits, i * cap, cap, max_hits, first_only,
            )  # fmt: skip
            if waiting >= 0:
                need[i] = waiting
                continue
            cnt = ist[i, 3]
            crossed[i] = ist[i, 4] != 0
            truncated[i] = cnt > max_hits
            cnt = min(cnt, max_hits)
            counts[i] = cnt
            status[i] = HIT if cnt > 0 else MISS
            phase[i] = 2
