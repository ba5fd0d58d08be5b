"""numba kernels that cast a batch of rays through angular indexes (arrays only).

A block of rays from one origin is set up at once (:func:`_set_up_lanes`, vectorised) and
each ray then walks its candidate bins (``core.raycast._angular_walk_kernels``); rays
between runs, or in azimuth bins not built, take the pyramid walk with the same answers.
Inputs are validated by ``core.raycast.cast``. The index kernels the tests reach through
this module (:func:`origin_runs_kernel`, :func:`pseudo_angle`, the slope classes) are
re-exported so that the angular kernels read as one namespace.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._angular_index_kernels import (
    origin_runs_kernel,
    pseudo_angle,
    slope_class,
    slope_class_edge,
    slope_class_top,
)
from ._angular_walk_kernels import (
    _angular_entry,
    _cast_one,
    _entry_lookup,
    _entry_terms,
    _origin_below,
    _prepare_shared,
    _ray_terms,
    next_candidate,
)
from ._block_claims import new_claims, next_block
from ._hit_kernels import load_direction_lanes
from ._walk_kernels import (
    BLOCK,
    HIT,
    MISS,
    SCRATCH_ROWS,
    prepare_row,
)

__all__ = [
    "_GEO_FIELDS",
    "_origin_below",
    "_set_up_lanes",
    "_store_lane",
    "cast_angular_kernel",
    "cast_angular_refill_kernel",
    "next_candidate",
    "origin_runs_kernel",
    "pseudo_angle",
    "slope_class",
    "slope_class_edge",
    "slope_class_top",
]

#: Fields of a block's set-up scratch (see :func:`_set_up_lanes`).
_GEO_FIELDS = 12


@njit(cache=True, error_model="numpy", inline="always")
def _store_lane(
    j, st, gx0, gy0, kx, ky, uz, t_a, t_end, d_rho, n_az, n_q, s_unit, geo, ent
):  # pragma: no cover - numba
    """Write one prepared ray's set-up into lane ``j`` of a block's scratch.

    ``geo`` (float64): 1 ``gx0``, 2 ``gy0``, 3 ``kx``, 4 ``ky``, 5 ``uz``, 6 ``t_a``,
    7 ``t_end``, 8 ``slope``, 9 ``step_t``, 10 ``ikx``, 11 ``iky`` (:func:`_ray_terms`);
    ``ent`` (int64): 0-3 :func:`_entry_terms`' answers, 4 the status. Field ``f`` of
    lane ``j`` is at ``f * SCRATCH_ROWS + j``.
    """
    R = SCRATCH_ROWS
    hk, slope, step_t, ikx, iky = _ray_terms(kx, ky, uz, d_rho)
    az_bin, q, b0, b1 = _entry_terms(kx, ky, hk, slope, t_a, t_end, n_az, n_q, s_unit, d_rho)
    geo[R + j] = gx0
    geo[2 * R + j] = gy0
    geo[3 * R + j] = kx
    geo[4 * R + j] = ky
    geo[5 * R + j] = uz
    geo[6 * R + j] = t_a
    geo[7 * R + j] = t_end
    geo[8 * R + j] = slope
    geo[9 * R + j] = step_t
    geo[10 * R + j] = ikx
    geo[11 * R + j] = iky
    ent[j] = az_bin
    ent[R + j] = q
    ent[2 * R + j] = b0
    ent[3 * R + j] = b1
    ent[4 * R + j] = st


@njit(cache=True, error_model="numpy", inline="always")
def _set_up_lanes(
    nrows,
    ncols,
    cell,
    z_min,
    z_max,
    margin,
    gxs,
    gys,
    oz,
    below,
    d_rho,
    n_az,
    n_q,
    s_unit,
    lane_in,
    geo,
    ent,
):  # pragma: no cover - numba
    """Set up a block of ``BLOCK`` rays from a run's origin, as one vectorised loop.

    ``lane_in`` holds the rays' ``dx, dy, dz, max_range`` in lanes (fields 0-3; lanes
    past the block's end hold any finite values, and their answers are not read).
    :func:`_prepare_shared`, :func:`_ray_terms` and :func:`_entry_terms` have no memory
    access and their branches are selects, so LLVM vectorises the whole set-up (AVX-512
    on this machine: 8 rays per division and square root, where the set-up of one ray
    waits on the divider); each lane's arithmetic is the scalar one, to the bit. Answers
    go to ``geo``, ``ent`` as in :func:`_store_lane`. The lanes are flat arrays at fixed
    offsets, not 2-D ones: with one base pointer per array LLVM proves the lanes apart.
    """
    R = SCRATCH_ROWS
    for j in range(BLOCK):
        st, kx, ky, uz, t_a, t_end = _prepare_shared(
            nrows,
            ncols,
            cell,
            z_min,
            z_max,
            margin,
            gxs,
            gys,
            oz,
            below,
            lane_in[j],
            lane_in[R + j],
            lane_in[2 * R + j],
            lane_in[3 * R + j],
        )
        _store_lane(j, st, gxs, gys, kx, ky, uz, t_a, t_end, d_rho, n_az, n_q, s_unit, geo, ent)


@njit(parallel=True, cache=True, error_model="numpy")
def cast_angular_kernel(
    elev,
    nodes,
    lvl_off,
    lvl_shape,
    x_min,
    y_max,
    cell,
    z_min,
    z_max,
    margin,
    origins,
    directions,
    max_range,
    first_only,
    max_hits,
    nthreads,
    tree,
    t_off,
    t_size,
    slot_of_az,
    d_rho,
    start,
    s_unit,
    lo,
    hi,
    buf,
    counts,
    status,
    crossed,
    truncated,
    unbuilt,
    shared,
):  # pragma: no cover - numba
    """``raycast_kernels.cast_kernel`` for rays ``lo:hi``, which share the index's origin.

    Same arguments and outputs as ``cast_kernel``, plus the angular index (``tree``
    float32 ``(n_slots, n_nodes, 2)``, ``t_off``/``t_size`` its level table,
    ``slot_of_az`` int32 ``(n_az,)``, ``d_rho`` range-bin width in cells, ``start``
    int32 ``(n_slots, n_q)`` and ``s_unit`` the slope classes' table). Rays whose
    azimuth bin was not built, and vertical rays, take the pyramid walk; ``unbuilt``
    (int64 ``(nthreads,)``, out) counts the non-vertical ones per thread, so the caller
    knows whether the index needs more bins. ``shared``: the rays really share
    ``origins[lo]`` (a run), so the per-origin part of the set-up is done once; with
    ``False`` (the rays between runs, with an index that has no bin built) each ray is
    set up on its own.
    """
    cap = buf.shape[1]
    hits = buf.reshape(buf.size)
    nrows, ncols = elev.shape
    nblocks = (hi - lo + BLOCK - 1) // BLOCK
    shared = shared and hi > lo
    gxs = 0.0
    gys = 0.0
    below = False
    if shared:  # as in _prepare
        gxs = (origins[lo, 0] - x_min) / cell - 0.5
        gys = (y_max - origins[lo, 1]) / cell - 0.5
        below = _origin_below(elev, nodes, lvl_off, lvl_shape, gxs, gys, origins[lo, 2])
    n_az = slot_of_az.shape[0]
    n_q = start.shape[1]
    R = SCRATCH_ROWS
    claims = new_claims()
    for th in prange(nthreads):
        n_unbuilt = 0
        # A block's rays are all set up and entered into the index first, then walked
        # (as in ``raycast_kernels.cast_kernel``: independent set-ups overlap their
        # latencies). Scratch in lanes: field ``f`` of the block's ray ``j`` at
        # ``f * SCRATCH_ROWS + j`` (see ``_set_up_lanes``).
        lane_in = np.ones(4 * R, np.float64)
        geo = np.empty(_GEO_FIELDS * R, np.float64)
        ent = np.empty(5 * R, np.int64)
        blk, stop = -1, 0
        while True:
            blk, stop = next_block(claims, blk, stop, nblocks)
            if blk >= nblocks:
                break
            q0 = lo + blk * BLOCK
            q1 = min(hi, q0 + BLOCK)
            if shared:
                load_direction_lanes(directions, q0, q1, lane_in)
                for i in range(q0, q1):
                    lane_in[3 * R + i - q0] = max_range[i]
                _set_up_lanes(
                    nrows,
                    ncols,
                    cell,
                    z_min,
                    z_max,
                    margin,
                    gxs,
                    gys,
                    origins[lo, 2],
                    below,
                    d_rho,
                    n_az,
                    n_q,
                    s_unit,
                    lane_in,
                    geo,
                    ent,
                )
            else:
                for i in range(q0, q1):
                    st, gx0, gy0, kx, ky, uz, t_a, t_end = prepare_row(
                        elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
                        origins, directions, max_range, i,
                    )  # fmt: skip
                    _store_lane(
                        i - q0,
                        st,
                        gx0,
                        gy0,
                        kx,
                        ky,
                        uz,
                        t_a,
                        t_end,
                        d_rho,
                        n_az,
                        n_q,
                        s_unit,
                        geo,
                        ent,
                    )
            for i in range(q0, q1):
                j = i - q0
                if ent[4 * R + j] == HIT:
                    ent[j], ent[R + j], ent[2 * R + j] = _entry_lookup(
                        ent[j],
                        ent[R + j],
                        ent[2 * R + j],
                        ent[3 * R + j],
                        geo[8 * R + j],
                        tree,
                        t_off,
                        t_size,
                        slot_of_az,
                        start,
                    )
            for i in range(q0, q1):
                j = i - q0
                crossed[i] = False
                truncated[i] = False
                counts[i] = 0
                st = ent[4 * R + j]
                if st != HIT:
                    status[i] = st
                    continue
                sl = ent[j]
                cnt, cr = _cast_one(
                    elev,
                    nodes,
                    lvl_off,
                    lvl_shape,
                    margin,
                    geo[R + j],
                    geo[2 * R + j],
                    origins[i, 2],
                    geo[3 * R + j],
                    geo[4 * R + j],
                    geo[5 * R + j],
                    geo[8 * R + j],
                    geo[9 * R + j],
                    geo[10 * R + j],
                    geo[11 * R + j],
                    geo[6 * R + j],
                    geo[7 * R + j],
                    tree,
                    t_off,
                    t_size,
                    sl,
                    ent[R + j],
                    ent[2 * R + j],
                    hits,
                    i * cap,
                    cap,
                    max_hits,
                    first_only,
                )
                if sl == -2:
                    n_unbuilt += 1
                crossed[i] = cr
                if cnt > max_hits:
                    truncated[i] = True
                    cnt = max_hits
                counts[i] = cnt
                status[i] = HIT if cnt > 0 else MISS
        unbuilt[th] = n_unbuilt


@njit(parallel=True, cache=True, error_model="numpy")
def cast_angular_refill_kernel(
    elev,
    nodes,
    lvl_off,
    lvl_shape,
    x_min,
    y_max,
    cell,
    z_min,
    z_max,
    margin,
    origins,
    directions,
    max_range,
    max_hits,
    tree,
    t_off,
    t_size,
    slot_of_az,
    d_rho,
    start,
    s_unit,
    rays,
    offsets,
    range_out,
):  # pragma: no cover - numba
    """Re-walk rays ``rays`` (int64; all from the index's origin) into their CSR slots.

    ``raycast_kernels.cast_all_refill_kernel`` through the angular index: the same walk
    as :func:`cast_angular_kernel`'s, so the same hits, all of them (up to ``max_hits``)
    written to ``range_out[offsets[i]:offsets[i + 1]]``.
    """
    for q in prange(rays.shape[0]):
        i = rays[q]
        st, gx0, gy0, kx, ky, uz, t_a, t_end = prepare_row(
            elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
            origins, directions, max_range, i,
        )  # fmt: skip
        if st != HIT:
            continue
        hk, slope, step_t, ikx, iky = _ray_terms(kx, ky, uz, d_rho)
        sl, b, b_end = _angular_entry(
            kx, ky, hk, slope, t_a, t_end, tree, t_off, t_size, slot_of_az, d_rho, start, s_unit
        )
        _cast_one(
            elev,
            nodes,
            lvl_off,
            lvl_shape,
            margin,
            gx0,
            gy0,
            origins[i, 2],
            kx,
            ky,
            uz,
            slope,
            step_t,
            ikx,
            iky,
            t_a,
            t_end,
            tree,
            t_off,
            t_size,
            sl,
            b,
            b_end,
            range_out,
            offsets[i],
            offsets[i + 1] - offsets[i],
            max_hits,
            False,
        )
