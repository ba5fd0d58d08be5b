"""The pyramid walk of one ray: set-up, patch solver and hierarchical DDA (numba, arrays only).

The primitives every DEM ray-casting kernel inlines or calls (``core.raycast._kernels``, the
light twin, the angular walk, the viewshed's sight lines); the kernels that loop over rays
live in their own modules. Inputs are validated by ``core.raycast.cast``.

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

No ``fastmath``: the kernels rely on NaN/inf semantics (holes, vertical rays) and on
IEEE rounding to agree with the reference twin; the speed comes from the pyramid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "BELOW_GROUND",
    "BLOCK",
    "DEDUPE_M",
    "HIT",
    "MISS",
    "OUTSIDE",
    "ROOT_WINDOW_M",
    "SCRATCH_ROWS",
    "UPWARD",
    "_prepare",
    "_walk",
    "has_holes",
    "keep_root",
    "patch_root",
    "prepare_row",
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


@njit(cache=True, error_model="numpy", inline="always")
def clip_to_hull(nrows, ncols, gx0, gy0, dx, dy, dz, cell, max_range):  # pragma: no cover
    """A ray's grid rates and its range over the hull of cell centres, within [0, max_range].

    ``gx0, gy0``: the origin in grid coordinates (``(ox - x_min) / cell - 0.5``, ``(y_max
    - oy) / cell - 0.5``). Returns ``(kx, ky, uz, t_lo, t_hi)``: the unit direction's
    grid rates and the range (empty when ``t_lo > t_hi``). Shared by the in-memory, the
    per-origin (angular) and the tiled set-ups, so all clip to the bit alike.
    """
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    ux = dx / norm
    uy = dy / norm
    uz = dz / norm
    kx = ux / cell
    ky = -uy / cell
    gxmax = ncols - 1.0
    gymax = nrows - 1.0
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
    return kx, ky, uz, t_lo, t_hi


@njit(cache=True, error_model="numpy", inline="always")
def bilinear(e00, e01, e10, e11, s, t):  # pragma: no cover - numba
    """The surface's height at ``(s, t)`` in a patch of corner heights ``e00 .. e11``."""
    return e00 * (1.0 - s) * (1.0 - t) + e01 * s * (1.0 - t) + e10 * (1.0 - s) * t + e11 * s * t


@njit(cache=True, error_model="numpy", inline="always")
def clip_to_slab(t_lo, t_hi, oz, uz, zlo, zhi):  # pragma: no cover - numba
    """``[t_lo, t_hi]`` narrowed to where the ray lies between heights ``zlo`` and ``zhi``."""
    if uz != 0.0:
        t1 = (zlo - oz) / uz
        t2 = (zhi - oz) / uz
        t_lo = max(t_lo, min(t1, t2))
        t_hi = min(t_hi, max(t1, t2))
    elif oz < zlo or oz > zhi:
        t_hi = -1.0
    return t_lo, t_hi


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
    gxmax = ncols - 1.0
    gymax = nrows - 1.0
    gx0 = (ox - x_min) / cell - 0.5
    gy0 = (y_max - oy) / cell - 0.5
    kx, ky, uz, t_lo, t_hi = clip_to_hull(nrows, ncols, gx0, gy0, dx, dy, dz, cell, max_range)
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
                if oz < bilinear(e00, e01, e10, e11, gx0 - ix, gy0 - iy):
                    return BELOW_GROUND, gx0, gy0, kx, ky, uz, 0.0, 0.0

    # Height slab of the terrain, with a margin so a roof at exactly z_max is inside.
    t_lo, t_hi = clip_to_slab(t_lo, t_hi, oz, uz, z_min - margin, z_max + margin)
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
def face_step(nx, ny, sx, sy, tmx, tmy, dxl, dyl):  # pragma: no cover - numba
    """One Amanatides-Woo step through the node face crossed first.

    Returns ``(nx, ny, tmx, tmy, t_cur, bx)``: the next node, its face ranges, the range
    at the face and whether the step was along x.
    """
    bx = tmx <= tmy
    t_cur = min(tmx, tmy)
    nx = nx + sx if bx else nx
    ny = ny if bx else ny + sy
    tmx = tmx + dxl if bx else tmx
    tmy = tmy if bx else tmy + dyl
    return nx, ny, tmx, tmy, t_cur, bx


@njit(cache=True, error_model="numpy", inline="always")
def climb_step(nx, ny, fx, fy, bx, level, top, tmx, tmy, dxl, dyl):  # pragma: no cover
    """After a step: climb one level when the ray entered a new parent by its near face.

    The parent's exit along an axis is one child width further when the ray is in the
    near child along that axis. Returns ``(nx, ny, level, tmx, tmy, dxl, dyl, climbed)``.
    """
    near_x = (nx & 1) != fx
    near_y = (ny & 1) != fy
    if (near_x if bx else near_y) and level < top:
        tmx = tmx + dxl if near_x else tmx
        tmy = tmy + dyl if near_y else tmy
        return nx >> 1, ny >> 1, level + 1, tmx, tmy, dxl * 2.0, dyl * 2.0, True
    return nx, ny, level, tmx, tmy, dxl, dyl, False


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
        nx, ny, tmx, tmy, t_cur, bx = face_step(nx, ny, sx, sy, tmx, tmy, dxl, dyl)
        if nx < 0 or nx >= ncl or ny < 0 or ny >= nrl:
            break
        z_cur = z_exit
        nx, ny, level, tmx, tmy, dxl, dyl, climbed = climb_step(
            nx, ny, fx, fy, bx, level, top, tmx, tmy, dxl, dyl
        )
        if climbed:
            ncl = lvl_shape[level - 1, 1]
            nrl = lvl_shape[level - 1, 0]
            koff = lvl_off[level - 1]
    return count, crossed


@njit(cache=True, error_model="numpy", inline="always")
def prepare_row(
    elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
    origins, directions, max_range, i,
):  # fmt: skip  # pragma: no cover - numba
    """:func:`_prepare` for ray ``i`` of the batch ``origins``, ``directions``, ``max_range``.

    The one place the casting kernels spell out the 17 arguments of the set-up: the DEM
    and pyramid, then row ``i`` of the rays. Inlined (no call, no tuple): the same
    arithmetic as calling :func:`_prepare` directly, bit for bit.
    """
    return _prepare(
        elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
        origins[i, 0], origins[i, 1], origins[i, 2],
        directions[i, 0], directions[i, 1], directions[i, 2], max_range[i],
    )  # fmt: skip
