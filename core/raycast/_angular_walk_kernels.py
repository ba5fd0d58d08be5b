"""The walk of one ray through an angular index: candidate bins, then the exact cell walk.

numba, arrays only. A ray finds its next candidate range bin in its azimuth's min/max tree
and runs the patch solver of ``core.raycast._walk_kernels`` only there; rays whose azimuth
bin is not built take the pyramid walk. The index itself is built by
``core.raycast._angular_index_kernels``; the casting loops are ``core.raycast._angular_kernels``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._angular_index_kernels import pseudo_angle, slope_class
from ._walk_kernels import (
    BELOW_GROUND,
    HIT,
    MISS,
    OUTSIDE,
    UPWARD,
    _walk,
    clip_to_hull,
    clip_to_slab,
    has_holes,
    keep_root,
    patch_root,
)

__all__ = [
    "SPAN_SLACK_M",
    "_angular_entry",
    "_cast_one",
    "_entry_lookup",
    "_entry_terms",
    "_origin_below",
    "_prepare_shared",
    "_ray_terms",
    "next_candidate",
]

#: Slack (m of ray range) on each side of a candidate stretch; crossings lie inside
#: candidate bins, this only absorbs the rounding of ``t * hk``.
SPAN_SLACK_M = 1e-7


@njit(cache=True, inline="always")
def _next_candidate(tree, sl, t_off, t_size, b, b_end, s):  # pragma: no cover - numba
    """First leaf ``>= b`` and ``<= b_end`` of slot ``sl``'s tree whose bounds contain ``s``.

    ``b_end + 1`` if none. The slot is indexed in place (``tree[sl, k, 0]``) rather than
    taken as a view per ray, so no per-ray array object is made.
    """
    top = t_off.shape[0] - 1
    lv = 0
    i = b
    while True:
        if (i << lv) > b_end:
            return b_end + 1
        k = t_off[lv] + i
        if tree[sl, k, 0] >= s and tree[sl, k, 1] <= s:
            if lv == 0:
                return i
            lv -= 1
            i <<= 1
        else:
            i += 1
            if i >= t_size[lv]:
                return b_end + 1
            # Entered a new parent through its first child: test the parent instead.
            while lv < top and (i & 1) == 0:
                i >>= 1
                lv += 1


@njit(cache=True)
def next_candidate(tr, t_off, t_size, b, b_end, s):  # pragma: no cover - numba
    """Callable form of the tree query on one slot's tree ``tr`` (for tests)."""
    return _next_candidate(tr.reshape((1, tr.shape[0], 2)), 0, t_off, t_size, b, b_end, s)


@njit(cache=True, error_model="numpy", inline="always")
def _walk_cells(
    elev,
    margin,
    holes,
    gx0,
    gy0,
    z0,
    kx,
    ky,
    uz,
    ikx,
    iky,
    t1,
    t2,
    hits,
    base,
    cap,
    max_count,
    first_only,
    count,
    last_t,
):  # pragma: no cover - numba
    """Walk the patches of ``[t1, t2]`` one by one (Amanatides-Woo at level 0).

    The per-patch work is exactly that of ``raycast_kernels._walk`` at level 0 (same
    tests, same solver, same acceptance window and de-duplication), continuing the
    ray's ``count`` and ``last_t``. ``ikx, iky``: :func:`_ray_terms`'; ``holes``:
    ``raycast_kernels.has_holes`` of the DEM. Returns
    ``(count, crossed, last_t, stop)``.
    """
    nrows, ncols = elev.shape
    pcols = ncols - 1
    prows = nrows - 1
    nx = min(max(int(math.floor(gx0 + t1 * kx)), 0), pcols - 1)
    ny = min(max(int(math.floor(gy0 + t1 * ky)), 0), prows - 1)
    fx = 1 if kx > 0.0 else 0
    fy = 1 if ky > 0.0 else 0
    sx = 1 if kx > 0.0 else -1
    sy = 1 if ky > 0.0 else -1
    dtx = abs(ikx)
    dty = abs(iky)
    tmx = ((nx + fx) - gx0) * ikx if kx != 0.0 else np.inf
    tmy = ((ny + fy) - gy0) * iky if ky != 0.0 else np.inf
    t_cur = t1
    z_cur = z0 + t1 * uz
    crossed = False
    stop = False
    while True:
        t_exit = max(min(min(tmx, tmy), t2), t_cur)
        z_exit = z0 + t_exit * uz
        zl = min(z_cur, z_exit) - margin
        zh = max(z_cur, z_exit) + margin
        s, hole = patch_root(elev, holes, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur, zl, zh)
        crossed = crossed or hole
        count, last_t, kept = keep_root(s, t_cur, t_exit, hits, base, cap, count, last_t)
        if kept and (first_only or count > max_count):
            stop = True
            break
        if t_exit >= t2:
            break
        # Which face is crossed is data-dependent (mispredicted about half the time on
        # a diagonal ray): selects, not branches.
        step_x = tmx <= tmy
        t_cur = tmx if step_x else tmy
        nx += sx if step_x else 0
        ny += 0 if step_x else sy
        tmx += dtx if step_x else 0.0
        tmy += 0.0 if step_x else dty
        if nx < 0 or nx >= pcols or ny < 0 or ny >= prows:
            break
        z_cur = z_exit
    return count, crossed, last_t, stop


@njit(cache=True, error_model="numpy")
def _origin_below(elev, nodes, lvl_off, lvl_shape, gx0, gy0, oz):  # pragma: no cover - numba
    """``raycast_kernels._prepare``'s below-ground test, which depends on the origin only."""
    nrows, ncols = elev.shape
    if gx0 >= 0.0 and gx0 <= ncols - 1.0 and gy0 >= 0.0 and gy0 <= nrows - 1.0:
        ix = min(int(math.floor(gx0)), ncols - 2)
        iy = min(int(math.floor(gy0)), nrows - 2)
        lv = min(4, lvl_off.shape[0])
        k = lvl_off[lv - 1] + (iy >> lv) * lvl_shape[lv - 1, 1] + (ix >> lv)
        if oz < nodes[k, 0]:
            e00 = elev[iy, ix]
            e01 = elev[iy, ix + 1]
            e10 = elev[iy + 1, ix]
            e11 = elev[iy + 1, ix + 1]
            if e00 == e00 and e01 == e01 and e10 == e10 and e11 == e11:
                s = gx0 - ix
                t = gy0 - iy
                h = (
                    e00 * (1.0 - s) * (1.0 - t)
                    + e01 * s * (1.0 - t)
                    + e10 * (1.0 - s) * t
                    + e11 * s * t
                )
                if oz < h:
                    return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def _prepare_shared(
    nrows, ncols, cell, z_min, z_max, margin, gx0, gy0, oz, below, dx, dy, dz, max_range
):  # pragma: no cover - numba
    """``raycast_kernels._prepare`` for a ray from a run's common origin.

    The origin's grid position ``gx0, gy0`` and its below-ground verdict ``below`` are
    computed once per run; the rest is ``_prepare``'s arithmetic, operation for
    operation, so the clipped stretch is the same to the bit. Returns ``(status, kx,
    ky, uz, t_a, t_end)``.
    """
    kx, ky, uz, t_lo, t_hi = clip_to_hull(nrows, ncols, gx0, gy0, dx, dy, dz, cell, max_range)
    if not (t_lo <= t_hi):
        return OUTSIDE, kx, ky, uz, 0.0, 0.0
    if uz >= 0.0 and oz >= z_max:
        return UPWARD, kx, ky, uz, 0.0, 0.0
    if below:
        return BELOW_GROUND, kx, ky, uz, 0.0, 0.0
    t_lo, t_hi = clip_to_slab(t_lo, t_hi, oz, uz, z_min - margin, z_max + margin)
    if not (t_lo <= t_hi):
        return MISS, kx, ky, uz, 0.0, 0.0
    return HIT, kx, ky, uz, t_lo, t_hi


@njit(cache=True, error_model="numpy", inline="always")
def _ray_terms(kx, ky, uz, d_rho):  # pragma: no cover - numba
    """A prepared ray's per-ray constants: ``(hk, slope, step_t, ikx, iky)``.

    ``hk`` the horizontal cells per metre along the ray, ``slope`` its rise per
    horizontal cell, ``step_t`` the ray length per range bin, ``ikx, iky`` the inverse
    grid steps of the cell walk (0 for an axis the ray does not move along). Computed
    in the set-up pass, where the rays' divisions and square roots overlap, rather than
    at the head of each walk, where they wait on one another.
    """
    hk = math.sqrt(kx * kx + ky * ky)
    slope = uz / hk
    step_t = d_rho / hk
    ikx = 1.0 / kx if kx != 0.0 else 0.0
    iky = 1.0 / ky if ky != 0.0 else 0.0
    return hk, slope, step_t, ikx, iky


@njit(cache=True, error_model="numpy", inline="always")
def _entry_terms(kx, ky, hk, slope, t_a, t_end, n_az, n_q, s_unit, d_rho):  # pragma: no cover
    """The arithmetic of a prepared ray's entry into an angular index (no table read).

    ``hk, slope``: :func:`_ray_terms`'. Returns ``(az_bin, q, b0, b1)``: the ray's
    azimuth bin (-1 for a vertical ray), slope class, and the range bins of ``t_a`` and
    ``t_end``. Branch-free once inlined (the branches are selects), so a loop over a
    block's rays is vectorised; :func:`_entry_lookup` then reads the tables.
    """
    vertical = not hk > 0.0
    p = 0.0 if vertical else pseudo_angle(kx, ky)
    az_bin = -1 if vertical else min(int(p * (n_az / 4.0)), n_az - 1)
    q = slope_class(0.0 if vertical else slope, n_q, s_unit)
    b0 = int(t_a * hk / d_rho)
    b1 = int(t_end * hk / d_rho)
    return az_bin, q, b0, b1


@njit(cache=True, error_model="numpy", inline="always")
def _entry_lookup(
    az_bin, q, b0, b1, slope, tree, t_off, t_size, slot_of_az, start
):  # pragma: no cover - numba
    """Where a ray enters the angular index, from :func:`_entry_terms`' answers.

    Returns ``(slot, b, b_end)``: the ray's slot, its first candidate range bin ``b``
    (``b_end + 1`` if none) and its last range bin; ``slot`` is -1 for a vertical ray
    and -2 for one whose azimuth bin is not built (both take the pyramid walk).
    """
    if az_bin < 0:
        return -1, 0, -1
    sl = slot_of_az[az_bin]
    if sl < 0:
        return -2, 0, -1
    n_r = t_size[0]
    b = max(min(b0, n_r - 1), start[sl, q, 0])
    b_end = min(b1, n_r - 1, start[sl, q, 1])
    return sl, _next_candidate(tree, sl, t_off, t_size, b, b_end, slope), b_end


@njit(cache=True, error_model="numpy", inline="always")
def _angular_entry(
    kx, ky, hk, slope, t_a, t_end, tree, t_off, t_size, slot_of_az, d_rho, start, s_unit
):  # pragma: no cover - numba
    """Where one prepared ray (``_prepare`` said HIT) enters the angular index.

    :func:`_entry_terms` then :func:`_entry_lookup`, for one ray.
    """
    az_bin, q, b0, b1 = _entry_terms(
        kx, ky, hk, slope, t_a, t_end, slot_of_az.shape[0], start.shape[1], s_unit, d_rho
    )
    return _entry_lookup(az_bin, q, b0, b1, slope, tree, t_off, t_size, slot_of_az, start)


@njit(cache=True, error_model="numpy", inline="always")
def _cast_one(
    elev,
    nodes,
    lvl_off,
    lvl_shape,
    margin,
    gx0,
    gy0,
    z0,
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
    hits,
    base,
    cap,
    max_hits,
    first_only,
):  # pragma: no cover - numba
    """Walk one prepared ray from the index's origin, entered by :func:`_angular_entry`.

    Through the angular index from candidate bin ``b`` of slot ``sl``, or the pyramid
    walk when ``sl < 0``; ``slope, step_t, ikx, iky``: :func:`_ray_terms`'. Returns
    ``(count, crossed)``.
    """
    if sl < 0:
        return _walk(
            elev,
            nodes,
            lvl_off,
            lvl_shape,
            margin,
            gx0,
            gy0,
            z0,
            kx,
            ky,
            uz,
            t_a,
            t_end,
            hits,
            base,
            cap,
            max_hits,
            first_only,
        )
    holes = has_holes(nodes, lvl_off)
    cnt = 0
    cr = False
    last_t = -np.inf
    while b <= b_end:
        e = b + 1
        while e <= b_end and tree[sl, e, 0] >= slope and tree[sl, e, 1] <= slope:
            e += 1
        t1 = max(t_a, b * step_t - SPAN_SLACK_M)
        t2 = min(t_end, e * step_t + SPAN_SLACK_M)
        if t1 <= t2:
            cnt, c2, last_t, stop = _walk_cells(
                elev,
                margin,
                holes,
                gx0,
                gy0,
                z0,
                kx,
                ky,
                uz,
                ikx,
                iky,
                t1,
                t2,
                hits,
                base,
                cap,
                max_hits,
                first_only,
                cnt,
                last_t,
            )
            cr = cr or c2
            if stop:
                break
        b = _next_candidate(tree, sl, t_off, t_size, e, b_end, slope)
    return cnt, cr
