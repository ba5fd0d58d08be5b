"""numba kernels that build the origin-specific angular index (arrays only).

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

Also the detector of runs of rays sharing one origin (:func:`origin_runs_kernel`), which
decides which rays are cast through an index. The walk through an index is
``core.raycast._angular_walk_kernels``, the casting loops ``core.raycast._angular_kernels``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = [
    "P_EPS",
    "RHO_EPS",
    "angular_leaves_kernel",
    "angular_tree_kernel",
    "azimuth_bins_kernel",
    "origin_runs_kernel",
    "pseudo_angle",
    "slope_class",
    "slope_class_edge",
    "slope_class_top",
]

#: Slack on a patch's pseudo-angle span (p units; a bin is about 1e-3 wide).
P_EPS = 1e-9
#: Slack on a patch's range span (cells).
RHO_EPS = 1e-7


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
