"""numba kernels of the DEM ray caster (arrays only; inputs are validated by ``core.raycast.cast``).

Geometry (see ``core.terrain.grid`` and ``core.raycast.pyramid``): rays are walked in grid
coordinates
``gx(t) = gx0 + t kx``, ``gy(t) = gy0 + t ky`` and ``z(t) = z0 + t uz`` where ``t`` is the
range in metres along the unit direction, ``kx = ux / cell``, ``ky = -uy / cell`` (rows
grow southwards). Patch ``(iy, ix)`` is the bilinear surface between the centres of cells
``(iy, ix) .. (iy+1, ix+1)``. Inside a patch the surface along the ray is a quadratic in
``t`` and so is ``f(t) = z(t) - h(t)``; a hit is a root where ``f`` goes from positive
(above) to negative (below), solved in closed form.

Traversal is the Amanatides-Woo grid walk generalised to the levels of the min/max pyramid
(a hierarchical DDA over a maximum mipmap): at level ``L`` the walk is in one node, knowing
where the ray enters it and the ranges ``tmx``, ``tmy`` at which it leaves through its x
and y faces. If the ray's height over that stretch is entirely above the node's max or
below its min, no crossing can be there and the node is skipped (step through the face
crossed first, adding one node width to that face's range); otherwise the walk descends
into the child the ray is in, and at level 0 it solves the patch. After a skip into a new
parent node the walk climbs back one level. Indices are integers and every skip moves one
node forward along the ray, so the walk always ends; descents are bounded by the levels.

Threads claim blocks of ``BLOCK`` rays in order as they go (``core.raycast._block_claims``), so
coherent runs of rays (one camera's pixels) are spread over all threads, and a thread
slowed by other load does not hold up the rest. Within a block every ray is set up
(normalised, clipped, classified) before the first is walked: the set-ups do not depend on
each other, so the cache misses of one (the below-ground test reads the grid under its
origin) overlap those of the next instead of waiting behind a whole walk (the bench's
incoherent rays cast about 15 % faster; the answers are the same).

No ``fastmath``: the kernels rely on NaN/inf semantics (holes, vertical rays) and on
IEEE rounding to agree with the reference twin; the speed comes from the pyramid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._block_claims import new_claims, next_block

__all__ = [
    "BELOW_GROUND",
    "HIT",
    "MISS",
    "OUTSIDE",
    "UPWARD",
    "build_pyramid_kernel",
    "cast_all_refill_kernel",
    "cast_kernel",
    "check_rays_kernel",
    "gather_hits_kernel",
    "has_holes",
    "hit_points_kernel",
    "ray_order_kernel",
]

# Status codes; ``core.raycast.cast.RayStatus`` mirrors them (a test checks).
HIT = 0
MISS = 1
UPWARD = 2
BELOW_GROUND = 3
OUTSIDE = 4

#: Rays per block claimed by a thread (coherent neighbours share a block).
BLOCK = 64
#: Rows of each thread's scratch for a block's set-ups (only ``BLOCK`` are used). Sized
#: well beyond a block on purpose: with scratch of exactly one block the two-thread
#: camera casts ran 5-8 % slower than with this (stable over repeated A/B runs), the
#: one-thread ones did not; the placement of small per-thread allocations (a cache line
#: shared by two threads, or stores aliasing loads 4 KiB apart) is the likely cause. numba
#: hoists these allocations out of the ``prange`` body into the start of each worker's chunk
#: (``parfor_lowering.hoist``): one scratch per thread and launch, never shared.
SCRATCH_ROWS = 10 * BLOCK
#: Slack (m of range) on each side of a patch's stretch when accepting a root, so a root
#: exactly on a patch edge, rounded to either side, is found by at least one patch.
ROOT_WINDOW_M = 1e-6
#: Crossings closer than this (m) to the previous one are the same crossing found twice.
DEDUPE_M = 1e-5
#: Side (cells, as a power of two) of the origin tiles :func:`ray_order_kernel` bins by.
ORDER_TILE_SHIFT = 6


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


# Not inlined (numba's default): called once per ray, so a call costs nothing measurable
# (demtrack bench raycast: same rays/s), while inlining it into every casting kernel made
# the cold compile of ``cast_kernel`` about 7 s of CPU longer.
@njit(cache=True, error_model="numpy")
def _prepare(
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
    ox,
    oy,
    oz,
    dx,
    dy,
    dz,
    max_range,
):  # pragma: no cover - numba
    """Classify one ray and clip it; returns ``(status, gx0, gy0, kx, ky, uz, t_a, t_end)``.

    ``status == HIT`` means "walk it" (it may still end as MISS).
    """
    nrows, ncols = elev.shape
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    ux = dx / norm
    uy = dy / norm
    uz = dz / norm
    kx = ux / cell
    ky = -uy / cell
    gx0 = (ox - x_min) / cell - 0.5
    gy0 = (y_max - oy) / cell - 0.5
    gxmax = ncols - 1.0
    gymax = nrows - 1.0

    # Footprint against the hull of cell centres, within [0, max_range].
    t_lo = 0.0
    t_hi = max_range
    if kx != 0.0:
        t1 = (0.0 - gx0) / kx
        t2 = (gxmax - gx0) / kx
        t_lo = max(t_lo, min(t1, t2))
        t_hi = min(t_hi, max(t1, t2))
    elif gx0 < 0.0 or gx0 > gxmax:
        t_hi = -1.0
    if ky != 0.0:
        t1 = (0.0 - gy0) / ky
        t2 = (gymax - gy0) / ky
        t_lo = max(t_lo, min(t1, t2))
        t_hi = min(t_hi, max(t1, t2))
    elif gy0 < 0.0 or gy0 > gymax:
        t_hi = -1.0
    if not (t_lo <= t_hi):
        return OUTSIDE, gx0, gy0, kx, ky, uz, 0.0, 0.0

    # Rising (or level) from at or above the highest terrain: f = z - h >= 0 for ever.
    if uz >= 0.0 and oz >= z_max:
        return UPWARD, gx0, gy0, kx, ky, uz, 0.0, 0.0

    # Origin under a valid part of the surface. A coarse pyramid node (small enough to
    # stay in cache) usually proves the origin is above, sparing a read of the grid.
    if gx0 >= 0.0 and gx0 <= gxmax and gy0 >= 0.0 and gy0 <= gymax:
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
                    return BELOW_GROUND, gx0, gy0, kx, ky, uz, 0.0, 0.0

    # Height slab of the terrain, with a margin so a roof at exactly z_max is inside.
    zlo = z_min - margin
    zhi = z_max + margin
    if uz != 0.0:
        t1 = (zlo - oz) / uz
        t2 = (zhi - oz) / uz
        t_lo = max(t_lo, min(t1, t2))
        t_hi = min(t_hi, max(t1, t2))
    elif oz < zlo or oz > zhi:
        t_hi = -1.0
    if not (t_lo <= t_hi):
        return MISS, gx0, gy0, kx, ky, uz, 0.0, 0.0
    return HIT, gx0, gy0, kx, ky, uz, t_lo, t_hi


@njit(cache=True, error_model="numpy", inline="always")
def _solve_patch(
    e00, e01, e10, e11, ix, iy, gx0, gy0, kx, ky, uz, t0, z_t0
):  # pragma: no cover - numba
    """Offset ``s`` from ``t0`` of the ray's down-crossing of patch ``(iy, ix)``.

    ``e00, e01, e10, e11`` are the corner elevations ``elev[iy, ix]``, ``elev[iy, ix+1]``,
    ``elev[iy+1, ix]``, ``elev[iy+1, ix+1]`` (finite). ``f(s) = z - h`` along the ray is
    ``qa s^2 + qb s + qc`` on the patch; the returned root is the one where
    ``f' = -sqrt(disc) < 0`` (above to below); NaN or +-inf when there is none (tangent,
    no real root, level surface).
    """
    b = e01 - e00
    c = e10 - e00
    d = e11 - e10 - e01 + e00
    ua = gx0 + t0 * kx - ix
    va = gy0 + t0 * ky - iy
    qa = -d * kx * ky
    qb = uz - (b * kx + c * ky + d * (ua * ky + va * kx))
    qc = z_t0 - (e00 + b * ua + c * va + d * ua * va)
    disc = qb * qb - 4.0 * qa * qc
    if not disc > 0.0:
        return np.nan
    sq = math.sqrt(disc)
    # Cancellation-free form of (-qb - sq) / (2 qa); qa == 0 gives the linear root.
    if qb >= 0.0:
        return -0.5 * (qb + sq) / qa
    return qc / (0.5 * (sq - qb))


@njit(cache=True, error_model="numpy")
def _solve_at(elev, iy, ix, gx0, gy0, kx, ky, uz, t0, z_t0):  # pragma: no cover - numba
    """``_solve_patch`` reading the corners from ``elev``; NaN for a hole."""
    e00 = np.float64(elev[iy, ix])
    e01 = np.float64(elev[iy, ix + 1])
    e10 = np.float64(elev[iy + 1, ix])
    e11 = np.float64(elev[iy + 1, ix + 1])
    if e00 != e00 or e01 != e01 or e10 != e10 or e11 != e11:
        return np.nan
    return _solve_patch(e00, e01, e10, e11, ix, iy, gx0, gy0, kx, ky, uz, t0, z_t0)


@njit(cache=True, inline="always")
def has_holes(nodes, lvl_off):  # pragma: no cover - numba
    """Whether the DEM under a min/max pyramid has a nodata cell (its root's max is +inf)."""
    return nodes[lvl_off[lvl_off.shape[0] - 1], 0] == np.inf


@njit(cache=True, error_model="numpy", inline="always")
def patch_root(elev, holes, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur, zl, zh):  # pragma: no cover
    """Where the ray crosses patch ``(ny, nx)`` from ``t_cur`` on; NaN when it does not.

    ``zl, zh`` bound the ray's height over the patch (with margin). Returns ``(s, hole)``:
    ``s`` the crossing's distance past ``t_cur``, ``hole`` whether the patch has a nodata
    corner (it cannot be hit). ``holes``: whether the DEM has any nodata cell
    (:func:`has_holes`); when it has none the corners are not tested for NaN (about 5 %
    of a camera ray's cast).
    """
    e00 = np.float64(elev[ny, nx])
    e01 = np.float64(elev[ny, nx + 1])
    e10 = np.float64(elev[ny + 1, nx])
    e11 = np.float64(elev[ny + 1, nx + 1])
    s = np.nan
    hole = False
    if holes and (e00 != e00 or e01 != e01 or e10 != e10 or e11 != e11):
        hole = True
        # A ray lying exactly on a grid line borders two patches (four at a vertex);
        # when the walked one is a hole the surface on the shared edge may still be
        # defined by the other one.
        on_x = kx == 0.0 and nx > 0 and gx0 == nx
        on_y = ky == 0.0 and ny > 0 and gy0 == ny
        if on_x:
            s = _solve_at(elev, ny, nx - 1, gx0, gy0, kx, ky, uz, t_cur, z_cur)
        if on_y and s != s:
            s = _solve_at(elev, ny - 1, nx, gx0, gy0, kx, ky, uz, t_cur, z_cur)
        if on_x and on_y and s != s:
            s = _solve_at(elev, ny - 1, nx - 1, gx0, gy0, kx, ky, uz, t_cur, z_cur)
    elif zl < max(max(e00, e01), max(e10, e11)) and zh > min(min(e00, e01), min(e10, e11)):
        s = _solve_patch(e00, e01, e10, e11, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur)
    return s, hole


@njit(cache=True, error_model="numpy", inline="always")
def keep_root(s, t_cur, t_exit, hits, base, cap, count, last_t):  # pragma: no cover - numba
    """Record a patch crossing ``s`` (past ``t_cur``) if it lies in the walked segment.

    Accepts roots within ``ROOT_WINDOW_M`` of ``[t_cur, t_exit]`` (clamped into it) that
    are more than ``DEDUPE_M`` past the previous hit. Returns ``(count, last_t, kept)``.
    """
    seg = t_exit - t_cur
    kept = False
    if s >= -ROOT_WINDOW_M and s <= seg + ROOT_WINDOW_M:
        t_hit = t_cur + min(max(s, 0.0), seg)
        if t_hit - last_t > DEDUPE_M:
            if count < cap:
                hits[base + count] = t_hit
            count += 1
            last_t = t_hit
            kept = True
    return count, last_t, kept


@njit(cache=True, error_model="numpy", inline="always")
def _walk(
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
    max_count,
    first_only,
):  # pragma: no cover - numba
    """Walk one clipped ray; store up to ``cap`` hit ranges in ``hits[base:]``.

    Returns ``(count, crossed_nodata)``; ``count`` stops growing at ``max_count + 1``
    (so ``count > max_count`` means truncated) or at 1 when ``first_only``.

    State: node ``(nx, ny)`` at ``level``, the ray's stretch in it starting at ``t_cur``,
    and the ranges ``tmx``, ``tmy`` where it leaves the node through its x and y faces
    (Amanatides-Woo's tMax). A step across a face adds one node width (``dxl``, ``dyl``,
    exact powers-of-two multiples of the per-patch widths) instead of recomputing from
    the position, which keeps the chain of dependent operations per step short. The
    choices inside a step are written as selects rather than branches: which face is
    crossed and whether the climb applies to each axis are data-dependent and would be
    mispredicted about half the time.
    """
    nrows, ncols = elev.shape
    pcols = ncols - 1
    prows = nrows - 1
    top = lvl_off.shape[0]
    holes = has_holes(nodes, lvl_off)
    ix0 = min(max(int(math.floor(gx0 + t_a * kx)), 0), pcols - 1)
    iy0 = min(max(int(math.floor(gy0 + t_a * ky)), 0), prows - 1)
    # Start at the coarsest level whose nodes are not much larger than the footprint.
    foot = (t_end - t_a) * max(abs(kx), abs(ky))
    # The largest level with 2**(level - 1) <= 0.25 foot + 2, in [1, top]: frexp's
    # exponent is floor(log2(v)) + 1.
    level = max(1, min(top, math.frexp(0.25 * foot + 2.0)[1]))
    fx = 1 if kx > 0.0 else 0
    fy = 1 if ky > 0.0 else 0
    sx = 1 if kx > 0.0 else -1
    sy = 1 if ky > 0.0 else -1
    ikx = 1.0 / kx if kx != 0.0 else 0.0
    iky = 1.0 / ky if ky != 0.0 else 0.0
    dxl = abs(ikx) * (1 << level)
    dyl = abs(iky) * (1 << level)
    nx = ix0 >> level
    ny = iy0 >> level
    tmx = (((nx + fx) << level) - gx0) * ikx if kx != 0.0 else np.inf
    tmy = (((ny + fy) << level) - gy0) * iky if ky != 0.0 else np.inf
    # Node-grid shapes per level (level 0 = patches) and node-table offsets.
    ncl = pcols if level == 0 else lvl_shape[level - 1, 1]
    nrl = prows if level == 0 else lvl_shape[level - 1, 0]
    koff = lvl_off[level - 1] if level > 0 else 0
    t_cur = t_a
    z_cur = z0 + t_a * uz
    count = 0
    crossed = False
    last_t = -np.inf
    while True:
        t_exit = max(min(min(tmx, tmy), t_end), t_cur)
        z_exit = z0 + t_exit * uz
        zl = min(z_cur, z_exit) - margin
        zh = max(z_cur, z_exit) + margin
        if level > 0:
            k = koff + ny * ncl + nx
            if zl < nodes[k, 0] and zh > nodes[k, 1]:
                # The ray may cross the surface in this node: go down into the child it
                # is in at t_cur (past the middle face: the far child). At the east and
                # south edges a node may have one child only; rounding at the domain
                # entry must not pick the missing one.
                level -= 1
                dxl *= 0.5
                dyl *= 0.5
                if level == 0:
                    ncl = pcols
                    nrl = prows
                else:
                    ncl = lvl_shape[level - 1, 1]
                    nrl = lvl_shape[level - 1, 0]
                    koff = lvl_off[level - 1]
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
                # Never index past the grid, whatever the rounding at the exit point.
                nx = min(nx, ncl - 1)
                ny = min(ny, nrl - 1)
                continue
        else:
            s, hole = patch_root(elev, holes, nx, ny, gx0, gy0, kx, ky, uz, t_cur, z_cur, zl, zh)
            crossed = crossed or hole
            count, last_t, kept = keep_root(s, t_cur, t_exit, hits, base, cap, count, last_t)
            if kept and (first_only or count > max_count):
                break
        # Nothing (more) in this node: step through the face crossed first.
        if t_exit >= t_end:
            break
        bx = tmx <= tmy
        t_cur = min(tmx, tmy)
        nx = nx + sx if bx else nx
        ny = ny if bx else ny + sy
        tmx = tmx + dxl if bx else tmx
        tmy = tmy if bx else tmy + dyl
        if nx < 0 or nx >= ncl or ny < 0 or ny >= nrl:
            break
        z_cur = z_exit
        # Entered a new parent through its near face: climb to it, one level. The
        # parent's exit along an axis is one child width further when the ray is in
        # the near child along that axis.
        near_x = (nx & 1) != fx
        near_y = (ny & 1) != fy
        if (near_x if bx else near_y) and level < top:
            tmx = tmx + dxl if near_x else tmx
            tmy = tmy + dyl if near_y else tmy
            nx >>= 1
            ny >>= 1
            level += 1
            dxl *= 2.0
            dyl *= 2.0
            ncl = lvl_shape[level - 1, 1]
            nrl = lvl_shape[level - 1, 0]
            koff = lvl_off[level - 1]
    return count, crossed


@njit(parallel=True, cache=True, error_model="numpy")
def cast_kernel(
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
    order,
    buf,
    counts,
    status,
    crossed,
    truncated,
):  # pragma: no cover - numba
    """Cast every ray; keep its first ``buf.shape[1]`` hit ranges in ``buf``.

    Parameters
    ----------
    elev : float32 (nrows, ncols); nodes, lvl_off, lvl_shape : the pyramid (core.raycast.pyramid)
    x_min, y_max, cell : grid georeferencing (m)
    z_min, z_max, margin : terrain height range and slack (m)
    origins, directions : float64 (n, 3), local frame; directions non-zero, any length
    max_range : float64 (n,), metres along the unit direction (may be inf)
    first_only : bool; max_hits : int >= 1; nthreads : numba's thread count
    order : int64 (n,) or (0,): the results of input row ``q`` go to row ``order[q]``
        of the outputs (the rays were copied in that order by :func:`ray_order_kernel`),
        or to row ``q`` when empty
    buf : float64 (n, K) C-contiguous out; counts : int64 (n,) out (hits found, capped
    at max_hits); status : int8 (n,) out; crossed, truncated : bool (n,) out.
    """
    n = origins.shape[0]
    cap = buf.shape[1]
    hits = buf.reshape(buf.size)
    nblocks = (n + BLOCK - 1) // BLOCK
    ordered = order.shape[0] > 0
    # Threads claim blocks in order as they finish the last (``core.raycast._block_claims``), so
    # coherent runs of rays (one camera's pixels) are shared by all threads and a thread
    # slowed by other load does not hold up the rest.
    claims = new_claims()
    for _th in prange(nthreads):
        # A block's rays are all set up first, then walked (see the module docstring).
        stat = np.empty(SCRATCH_ROWS, np.int8)
        geo = np.empty((SCRATCH_ROWS, 7), np.float64)
        blk, stop = -1, 0
        while True:
            blk, stop = next_block(claims, blk, stop, nblocks)
            if blk >= nblocks:
                break
            q0 = blk * BLOCK
            q1 = min(n, q0 + BLOCK)
            for q in range(q0, q1):
                j = q - q0
                (
                    stat[j],
                    geo[j, 0],
                    geo[j, 1],
                    geo[j, 2],
                    geo[j, 3],
                    geo[j, 4],
                    geo[j, 5],
                    geo[j, 6],
                ) = _prepare(
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
                    origins[q, 0],
                    origins[q, 1],
                    origins[q, 2],
                    directions[q, 0],
                    directions[q, 1],
                    directions[q, 2],
                    max_range[q],
                )
            for q in range(q0, q1):
                j = q - q0
                # Outputs through the order (stores do not stall the walk as loads do).
                i = order[q] if ordered else q
                st = stat[j]
                if st != HIT:
                    crossed[i] = False
                    truncated[i] = False
                    counts[i] = 0
                    status[i] = st
                    continue
                cnt, cr = _walk(
                    elev,
                    nodes,
                    lvl_off,
                    lvl_shape,
                    margin,
                    geo[j, 0],
                    geo[j, 1],
                    origins[q, 2],
                    geo[j, 2],
                    geo[j, 3],
                    geo[j, 4],
                    geo[j, 5],
                    geo[j, 6],
                    hits,
                    i * cap,
                    cap,
                    max_hits,
                    first_only,
                )
                crossed[i] = cr
                truncated[i] = cnt > max_hits
                cnt = min(cnt, max_hits)
                counts[i] = cnt
                status[i] = HIT if cnt > 0 else MISS


@njit(parallel=True, cache=True, error_model="numpy")
def cast_all_refill_kernel(
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
    rays,
    offsets,
    range_out,
):  # pragma: no cover - numba
    """Re-walk the rays ``rays`` (int64) writing all their hits into ``range_out`` (CSR)."""
    for q in prange(rays.shape[0]):
        i = rays[q]
        st, gx0, gy0, kx, ky, uz, t_a, t_end = _prepare(
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
            origins[i, 0],
            origins[i, 1],
            origins[i, 2],
            directions[i, 0],
            directions[i, 1],
            directions[i, 2],
            max_range[i],
        )
        _walk(
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
            t_a,
            t_end,
            range_out,
            offsets[i],
            offsets[i + 1] - offsets[i],
            max_hits,
            False,
        )


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
