"""numba kernels of the origin-specific angular index (see ``core.raycast.angular_index``).

Rays that share an origin ``O`` are radial lines in plan view: each keeps one azimuth, and
its height at horizontal distance ``rho`` (in cells) from ``O`` is ``O_z + s rho`` with a
constant slope ``s`` (m per cell). A terrain point at distance ``rho`` is below the ray iff
its *angle* ``(z - O_z) / rho`` is below ``s``, so a crossing can only be where the
terrain's angle equals ``s``. The index stores, for polar bins (azimuth ``a`` x range
``b``), bounds ``[min_angle, max_angle]`` of the terrain's angle over the bin, and per
azimuth a 1-D min/max tree over range. A ray then finds its next candidate range bin in
``O(log n)`` and runs the exact cell walk (the patch solver of ``core.raycast._kernels``)
only there.

Azimuth is a *pseudo-angle* ``p`` in ``[0, 4)`` (the "diamond angle": ``dy / (|dx| +
|dy|)`` per quadrant), a strictly increasing function of the true angle, so a convex
patch's span is still the span of its corners, without ``atan2``. It is computed in grid
coordinates (``gx`` east, ``gy`` south), so ``p`` turns clockwise on the map; only
consistency between patches and rays matters.

Bins are conservative: each takes the largest and smallest corner elevation of every patch
touching it (a bilinear patch lies between its corners), widened by a height margin, and
divided by the bin's nearest or farthest range as the sign demands; holes (a NaN corner)
are ``[-inf, +inf]`` so that a ray passing over them walks them and flags them, exactly as
the pyramid walk does. Empty bins (outside the DEM) are ``[+inf, -inf]``: never walked.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._block_claims import new_claims, next_block
from ._kernels import (
    BELOW_GROUND,
    BLOCK,
    HIT,
    MISS,
    OUTSIDE,
    SCRATCH_ROWS,
    UPWARD,
    _prepare,
    _walk,
    has_holes,
    keep_root,
    load_direction_lanes,
    patch_root,
)

__all__ = [
    "angular_leaves_kernel",
    "angular_tree_kernel",
    "azimuth_bins_kernel",
    "origin_runs_kernel",
    "cast_angular_kernel",
    "cast_angular_refill_kernel",
    "next_candidate",
    "pseudo_angle",
    "slope_class",
    "slope_class_edge",
    "slope_class_top",
]

#: Slack on a patch's pseudo-angle span (p units; a bin is about 1e-3 wide).
P_EPS = 1e-9
#: Slack on a patch's range span (cells).
RHO_EPS = 1e-7
#: Slack (m of ray range) on each side of a candidate stretch; crossings lie inside
#: candidate bins, this only absorbs the rounding of ``t * hk``.
SPAN_SLACK_M = 1e-7


@njit(cache=True, inline="always")
def pseudo_angle(dx, dy):  # pragma: no cover - numba
    """Diamond angle of ``(dx, dy)`` in ``[0, 4)``, increasing with ``atan2(dy, dx)``."""
    if dy >= 0.0:
        if dx >= 0.0:
            return dy / (dx + dy)
        return 1.0 + (-dx) / (dy - dx)
    if dx < 0.0:
        return 2.0 + (-dy) / (-dx - dy)
    return 3.0 + dx / (dx - dy)


@njit(cache=True, inline="always")
def _scatter_prim(
    zmax,
    zmin,
    gxo,
    gyo,
    x0,
    x1,
    y0,
    y1,
    hi,
    lo,
    b0,
    b1,
    n_az,
    d_rho,
    slot_of_az,
    new_from,
):  # pragma: no cover - numba
    """Max/min one patch into the polar bins it touches.

    The patch is the grid rectangle ``[x0, x1] x [y0, y1]`` with heights ``lo..hi``; only
    range bins in ``[b0, b1)`` and slots ``>= new_from`` are written.
    """
    rx0 = x0 - gxo
    rx1 = x1 - gxo
    ry0 = y0 - gyo
    ry1 = y1 - gyo
    cx = min(max(0.0, rx0), rx1)
    cy = min(max(0.0, ry0), ry1)
    rmin = math.sqrt(cx * cx + cy * cy)
    ax = max(abs(rx0), abs(rx1))
    ay = max(abs(ry0), abs(ry1))
    rmax = math.sqrt(ax * ax + ay * ay)
    blo = max(b0, int(math.floor((rmin - RHO_EPS) / d_rho)))
    bhi = min(b1 - 1, int(math.floor((rmax + RHO_EPS) / d_rho)))
    if blo > bhi:
        return
    kaz = n_az / 4.0
    if rx0 <= 0.0 and rx1 >= 0.0 and ry0 <= 0.0 and ry1 >= 0.0:
        a_lo = 0
        a_hi = n_az - 1
    else:
        p00 = pseudo_angle(rx0, ry0)
        p01 = pseudo_angle(rx1, ry0)
        p10 = pseudo_angle(rx0, ry1)
        p11 = pseudo_angle(rx1, ry1)
        if rx0 > 0.0 and ry0 < 0.0 and ry1 >= 0.0:
            # Straddles the cut (p = 0 = 4 on +gx): corners with dy < 0 are near 4.
            plo = min(p00, p01) - 4.0
            phi = max(p10, p11)
        else:
            plo = min(min(p00, p01), min(p10, p11))
            phi = max(max(p00, p01), max(p10, p11))
        a_lo = int(math.floor((plo - P_EPS) * kaz))
        a_hi = int(math.floor((phi + P_EPS) * kaz))
        if a_hi - a_lo >= n_az:
            a_lo = 0
            a_hi = n_az - 1
    for a in range(a_lo, a_hi + 1):
        sl = slot_of_az[a % n_az]
        if sl < new_from:
            continue
        for b in range(blo, bhi + 1):
            if hi > zmax[sl - new_from, b]:
                zmax[sl - new_from, b] = hi
            if lo < zmin[sl - new_from, b]:
                zmin[sl - new_from, b] = lo


@njit(cache=True, inline="always")
def _cone_strip(cone, y0, y1):  # pragma: no cover - numba
    """x-extent ``(xa, xb)`` of the cone's part in the strip ``y0 <= y <= y1``.

    Coordinates are relative to the apex; ``xa > xb`` when empty, +-1e308 when unbounded.
    """
    xa = np.inf
    xb = -np.inf
    if y0 <= 0.0 and y1 >= 0.0:
        xa = 0.0
        xb = 0.0
    for k in range(2):
        dx = cone[1 + 2 * k]
        dy = cone[2 + 2 * k]
        if dy != 0.0:
            for yy in (y0, y1):
                t = yy / dy
                if t >= 0.0:
                    xa = min(xa, t * dx)
                    xb = max(xb, t * dx)
        elif y0 <= 0.0 and y1 >= 0.0:
            if dx > 0.0:
                xb = 1e308
            else:
                xa = -1e308
    # A cone narrower than half a turn meets a strip in a convex set whose corners are
    # among those points, unbounded towards +gx (-gx) when the cone holds that direction.
    flags = int(cone[5])
    if xa <= xb:
        if flags & 1:
            xb = 1e308
        if flags & 2:
            xa = -1e308
    return xa, xb


@njit(parallel=True, cache=True, error_model="numpy")
def angular_leaves_kernel(
    elev, gxo, gyo, n_az, d_rho, slot_of_az, new_from, cone, nthreads, nchunks, zmax, zmin
):  # pragma: no cover - numba
    """Largest/smallest terrain height per polar bin, for slots ``>= new_from``.

    Parameters
    ----------
    elev : float32 (nrows, ncols), NaN = nodata
    gxo, gyo : origin in grid coordinates
    n_az : azimuth bins; d_rho : range-bin width (cells)
    slot_of_az : int32 (n_az,), slot of each azimuth bin (-1 = not built)
    new_from : first slot to fill
    cone : float64 (6,): ``(use, d0x, d0y, d1x, d1y, flags)``; when ``use``, only
        patches in the cone from direction ``d0`` counter-clockwise to ``d1`` (grid
        frame, less than half a turn) are needed; ``flags`` bit 1: the cone holds
        ``+gx``, bit 2: it holds ``-gx``
    nthreads, nchunks : threads, and range chunks handed out round-robin
    zmax, zmin : float32 (n_new, n_r), prefilled with -inf / +inf; out. Holes give
        ``+inf`` / ``-inf``.

    Threads own disjoint chunks of range bins, so no two write the same bin; each chunk
    visits only the patch rows and columns that can reach its annulus.
    """
    nrows, ncols = elev.shape
    prows = nrows - 1
    pcols = ncols - 1
    n_r = zmax.shape[1]
    for th in prange(nthreads):
        for c in range(th, nchunks, nthreads):
            b0 = c * n_r // nchunks
            b1 = (c + 1) * n_r // nchunks
            if b0 >= b1:
                continue
            r_out = b1 * d_rho + 1.0
            r_in = b0 * d_rho - 1.0
            for i in range(prows):
                ry0 = i - gyo
                ry1 = ry0 + 1.0
                dymin = 0.0 if (ry0 <= 0.0 and ry1 >= 0.0) else min(abs(ry0), abs(ry1))
                dymax = max(abs(ry0), abs(ry1))
                if dymin > r_out:
                    continue
                xr = math.sqrt(r_out * r_out - dymin * dymin)
                j_lo = max(0, int(math.floor(gxo - xr)) - 1)
                j_hi = min(pcols - 1, int(math.ceil(gxo + xr)) + 1)
                if cone[0] != 0.0:
                    xa, xb = _cone_strip(cone, ry0, ry1)
                    if xa > xb:
                        continue
                    if xa > -1e300:
                        j_lo = max(j_lo, int(math.floor(gxo + xa)) - 1)
                    if xb < 1e300:
                        j_hi = min(j_hi, int(math.ceil(gxo + xb)) + 1)
                # Patches wholly inside the inner circle cannot reach this annulus.
                ja = 1
                jb = 0
                if r_in > dymax:
                    xi = math.sqrt(r_in * r_in - dymax * dymax)
                    ja = int(math.ceil(gxo - xi))
                    jb = int(math.floor(gxo + xi - 1.0))
                j = j_lo
                while j <= j_hi:
                    if j >= ja and j <= jb:
                        j = jb + 1
                        continue
                    e00 = elev[i, j]
                    e01 = elev[i, j + 1]
                    e10 = elev[i + 1, j]
                    e11 = elev[i + 1, j + 1]
                    if e00 != e00 or e01 != e01 or e10 != e10 or e11 != e11:
                        hi = np.float32(np.inf)
                        lo = np.float32(-np.inf)
                    else:
                        hi = max(max(e00, e01), max(e10, e11))
                        lo = min(min(e00, e01), min(e10, e11))
                    _scatter_prim(
                        zmax,
                        zmin,
                        gxo,
                        gyo,
                        float(j),
                        float(j + 1),
                        float(i),
                        float(i + 1),
                        hi,
                        lo,
                        b0,
                        b1,
                        n_az,
                        d_rho,
                        slot_of_az,
                        new_from,
                    )
                    j += 1


@njit(parallel=True, cache=True, error_model="numpy")
def angular_tree_kernel(
    zmax, zmin, oz, d_rho, margin, s_unit, tree, t_off, t_size, start, first
):  # pragma: no cover - numba
    """Turn heights into angle bounds; fill the upper tree levels and the start table.

    ``tree[first + k]`` (float32 ``(n_nodes, 2)``: max angle, min angle; m per cell) is
    built from ``zmax[k]``, ``zmin[k]`` (heights, m). Level ``l`` of a slot's tree starts
    at ``t_off[l]`` and has ``t_size[l]`` nodes; node ``i`` covers leaves
    ``[i 2^l, (i + 1) 2^l)``. Bounds are rounded outwards to float32.
    ``start[first + k, q, 0]`` (int32) is the first leaf whose max angle reaches the lower
    edge of slope class ``q`` (see :func:`slope_class`): no ray of that class can cross
    the terrain before it. ``start[first + k, q, 1]`` is the last leaf whose bounds can
    hold a slope of the class (max angle at or above its lower edge, min angle at or
    below its upper edge), -1 if none: no ray of the class can cross after it.
    """
    n_new, n_r = zmax.shape
    top = t_off.shape[0]
    n_q = start.shape[1]
    edges = np.empty(n_q)
    tops = np.empty(n_q)
    for q in range(n_q):
        edges[q] = slope_class_edge(q, n_q, s_unit)
        tops[q] = slope_class_top(q, n_q, s_unit)
    for k in prange(n_new):
        tr = tree[first + k]
        for b in range(n_r):
            r_lo = b * d_rho
            r_hi = (b + 1) * d_rho
            hz = np.float64(zmax[k, b])
            lz = np.float64(zmin[k, b])
            if hz == -np.inf:  # empty bin
                amax = -np.inf
                amin = np.inf
            else:
                num = hz + margin - oz
                if num >= 0.0:
                    amax = num / r_lo if r_lo > 0.0 else np.inf
                else:
                    amax = num / r_hi
                num = lz - margin - oz
                if num >= 0.0:
                    amin = num / r_hi
                else:
                    amin = num / r_lo if r_lo > 0.0 else -np.inf
            vmax = np.float32(amax)
            if np.float64(vmax) < amax:
                vmax = np.nextafter(vmax, np.float32(np.inf))
            vmin = np.float32(amin)
            if np.float64(vmin) > amin:
                vmin = np.nextafter(vmin, np.float32(-np.inf))
            tr[b, 0] = vmax
            tr[b, 1] = vmin
        for lv in range(1, top):
            co = t_off[lv - 1]
            cn = t_size[lv - 1]
            po = t_off[lv]
            for i in range(t_size[lv]):
                c0 = co + 2 * i
                if 2 * i + 1 < cn:
                    tr[po + i, 0] = max(tr[c0, 0], tr[c0 + 1, 0])
                    tr[po + i, 1] = min(tr[c0, 1], tr[c0 + 1, 1])
                else:
                    tr[po + i, 0] = tr[c0, 0]
                    tr[po + i, 1] = tr[c0, 1]
        b = 0
        for q in range(n_q):
            lo_q = edges[q]
            while b < n_r and not tr[b, 0] >= lo_q:
                b += 1
            start[first + k, q, 0] = b
        # Last leaf with max >= the lower edge (moves down as q rises) and last leaf with
        # min <= the upper edge (moves up as q rises); the class's end is the lower one.
        b = n_r - 1
        for q in range(n_q):
            while b >= 0 and not tr[b, 0] >= edges[q]:
                b -= 1
            start[first + k, q, 1] = b
        b = n_r - 1
        for q in range(n_q - 1, -1, -1):
            while b >= 0 and not tr[b, 1] <= tops[q]:
                b -= 1
            start[first + k, q, 1] = min(start[first + k, q, 1], b)


@njit(cache=True, inline="always")
def slope_class(s, n_q, s_unit):  # pragma: no cover - numba
    """Class ``q`` in ``[0, n_q)`` of slope ``s``: uniform in ``w = s / (|s| + s_unit)``."""
    w = s / (abs(s) + s_unit)
    return min(max(int((w + 1.0) * (0.5 * n_q)), 0), n_q - 1)


@njit(cache=True, inline="always")
def _class_boundary(q, n_q, s_unit, side):  # pragma: no cover - numba
    """The slope where class ``q`` begins, moved by a slack to ``side`` (-1 or +1).

    ``±inf`` beyond the outermost boundaries (``w = ±1``).
    """
    w = -1.0 + 2.0 * q / n_q
    if abs(w) >= 1.0:
        return w * np.inf
    s = s_unit * w / (1.0 - abs(w))
    return s + side * 1e-9 * (abs(s) + s_unit)


@njit(cache=True, inline="always")
def slope_class_edge(q, n_q, s_unit):  # pragma: no cover - numba
    """A slope at or below every slope of class ``q`` (its lower edge, less a slack)."""
    return _class_boundary(q, n_q, s_unit, -1.0)


@njit(cache=True, inline="always")
def slope_class_top(q, n_q, s_unit):  # pragma: no cover - numba
    """A slope at or above every slope of class ``q`` (its upper edge, plus a slack)."""
    return _class_boundary(q + 1, n_q, s_unit, 1.0)


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
def azimuth_bins_kernel(directions, lo, hi, cell, want):  # pragma: no cover - numba
    """Flag in ``want`` (bool ``(n_az,)``) the azimuth bin of every ray ``lo:hi``.

    Same arithmetic as ``cast_angular_kernel`` (so the same bins); level rays flag none.
    """
    n_az = want.shape[0]
    kaz = n_az / 4.0
    for i in range(lo, hi):
        dx = directions[i, 0]
        dy = directions[i, 1]
        dz = directions[i, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        kx = dx / norm / cell
        ky = -(dy / norm) / cell
        if kx != 0.0 or ky != 0.0:
            want[min(int(pseudo_angle(kx, ky) * kaz), n_az - 1)] = True


@njit(cache=True, inline="always")
def _same_origin(origins, a, b):  # pragma: no cover - numba
    return (
        origins[a, 0] == origins[b, 0]
        and origins[a, 1] == origins[b, 1]
        and origins[a, 2] == origins[b, 2]
    )


@njit(parallel=True, cache=True)
def origin_runs_kernel(origins, min_run, nt):  # pragma: no cover - numba
    """Runs of consecutive rays with bit-identical origins, at least ``min_run`` long.

    Returns int64 ``(k, 2)``: ``[start, stop)`` of each run, in order. Each of ``nt``
    shares (numba's thread count) is scanned on its own, keeping its long runs and the
    runs touching its ends; those are then joined across the shares' seams.
    """
    n = origins.shape[0]
    m = max(min_run, 1)
    per = (n + nt - 1) // nt
    seg = np.empty((nt, per // m + 3, 2), np.int64)
    nseg = np.zeros(nt, np.int64)
    for t in prange(nt):
        c0 = t * n // nt
        c1 = (t + 1) * n // nt
        k = 0
        a = c0
        while a < c1:
            b = a + 1
            while b < c1 and _same_origin(origins, b, a):
                b += 1
            if b - a >= m or a == c0 or b == c1:
                seg[t, k, 0] = a
                seg[t, k, 1] = b
                k += 1
            a = b
        nseg[t] = k
    out = np.empty((n // m + 1, 2), np.int64)
    k = 0
    a = -1
    b = -1
    for t in range(nt):
        for j in range(nseg[t]):
            s0 = seg[t, j, 0]
            s1 = seg[t, j, 1]
            if s0 == b and _same_origin(origins, s0, a):
                b = s1  # the same run, cut by a seam
                continue
            if b - a >= m and a >= 0:
                out[k, 0] = a
                out[k, 1] = b
                k += 1
            a = s0
            b = s1
    if b - a >= m and a >= 0:
        out[k, 0] = a
        out[k, 1] = b
        k += 1
    return out[:k].copy()


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
    if not (t_lo <= t_hi):
        return OUTSIDE, kx, ky, uz, 0.0, 0.0
    if uz >= 0.0 and oz >= z_max:
        return UPWARD, kx, ky, uz, 0.0, 0.0
    if below:
        return BELOW_GROUND, kx, ky, uz, 0.0, 0.0
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
