"""numba kernels of the fast viewshed (arrays only; ``core.visibility.viewshed`` validates inputs).

The horizon sweep works outwards from the observer ring by ring (Chebyshev rings of
cells around the observer's cell), one quadrant per thread. In a quadrant's canonical
frame ``u`` counts rings outwards and ``v`` runs across them: for the east quadrant
``u = column - observer column`` and ``v = row - observer row``; west, south and north are
mirror images or transposes. The sight line from the observer to the centre of cell
``(u = k, v = j)`` crosses the line of cell centres ``u = k - 1`` at ``v'``. Along that
line the bilinear surface is the linear interpolation of the two centres around ``v'``,
so the terrain sample there is exact; the horizon of the cells before it (the steepest
slope ``(z - z_obs) / horizontal distance`` seen so far along the line) is interpolated
between the horizons of those same two cells (the XDraw / reference-plane idea, as in
GDAL's ``gdal_viewshed``). The cell's horizon is the larger of the two.

The kernel writes, per cell, the *margin* ``z_target - z_obs - horizon * d``: metres by
which the target point clears the interpolated horizon (``d`` the horizontal distance).
Positive means probably visible. The interpolation is the only approximation, so the
caller re-checks with exact sight lines every cell whose margin is small or whose
neighbours disagree. ``NaN`` marks cells the sweep cannot judge (holes on the way, the
observer's own cell). ``core.visibility.reference`` is the plain-numpy twin.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..raycast import _walk_kernels as _rk

__all__ = [
    "NO_HORIZON",
    "boundary_kernel",
    "candidates_kernel",
    "grow_kernel",
    "refine_kernel",
    "sweep_margin_kernel",
]

#: Horizon slope before any terrain (finite, so that interpolation weights of 0 stay 0).
NO_HORIZON = -1.0e30
#: Rounds of at least this many sight lines are cast in parallel.
_PARALLEL_MIN = 2048


@njit(cache=True, inline="always")
def _to_cell(q, oc, orr, u, v):  # pragma: no cover - numba
    """Canonical ``(u, v)`` of quadrant ``q`` (0 E, 1 W, 2 S, 3 N) -> ``(row, col)``."""
    if q == 0:
        return orr + v, oc + u
    if q == 1:
        return orr + v, oc - u
    if q == 2:
        return orr + u, oc + v
    return orr - u, oc + v


@njit(parallel=True, cache=True)
def sweep_margin_kernel(
    elev, ogx, ogy, z_obs, cell, target_h, curv, margin, slack
):  # pragma: no cover - numba
    """Fill ``margin`` (float32, shape of ``elev``) with each cell's horizon margin (m).

    Parameters
    ----------
    elev : float32 (nrows, ncols), NaN = nodata
    ogx, ogy : observer in grid coordinates (fractional column, row); inside the grid
    z_obs : observer height (m, local frame Z)
    cell : cell edge (m)
    target_h : target height above the surface (m)
    curv : curvature factor (1/m): targets are lowered by ``curv * d**2``
    margin : float32 (nrows, ncols) out; NaN where undecided.
    slack : float32 (nrows, ncols) out; how far (m) the interpolated horizons the margin
        rests on could be off: the spread of the two horizons interpolated between, the
        largest along the line, times the distance (0 where the terrain on the line sets
        the horizon).
    """
    nrows, ncols = elev.shape
    oc = int(math.floor(ogx + 0.5))
    orr = int(math.floor(ogy + 0.5))
    oc = min(max(oc, 0), ncols - 1)
    orr = min(max(orr, 0), nrows - 1)
    margin[orr, oc] = np.nan
    slack[orr, oc] = 0.0
    for q in prange(4):
        if q == 0:
            kmax, vmin, vmax, ou, ov = ncols - 1 - oc, -orr, nrows - 1 - orr, ogx - oc, ogy - orr
        elif q == 1:
            kmax, vmin, vmax, ou, ov = oc, -orr, nrows - 1 - orr, oc - ogx, ogy - orr
        elif q == 2:
            kmax, vmin, vmax, ou, ov = nrows - 1 - orr, -oc, ncols - 1 - oc, ogy - orr, ogx - oc
        else:
            kmax, vmin, vmax, ou, ov = orr, -oc, ncols - 1 - oc, orr - ogy, ogx - oc
        width = vmax - vmin + 1
        prev = np.full(width, NO_HORIZON)
        cur = np.full(width, NO_HORIZON)
        prev_u = np.zeros(width)
        cur_u = np.zeros(width)
        for k in range(1, kmax + 1):
            lo = max(-k, vmin)
            hi = min(k, vmax)
            plo = max(-(k - 1), vmin)  # the previous ring's stretch of v
            phi = min(k - 1, vmax)
            du = k - ou
            dup = k - 1 - ou  # canonical distance of the crossing line u = k - 1
            for j in range(lo, hi + 1):
                r, c = _to_cell(q, oc, orr, k, j)
                dv = j - ov
                vp = ov + dv * dup / du  # where the sight line crosses u = k - 1
                # Horizon of everything before that line, interpolated across it.
                vh = min(max(vp, plo), phi)
                a = int(math.floor(vh))
                b = min(a + 1, phi)
                f = vh - a
                ha = prev[a - vmin]
                hb = prev[b - vmin]
                h = ha * (1.0 - f) + hb * f if b != a else ha
                # How far off the interpolated horizon may be: the spread of the two
                # horizons it mixes, or what the line inherited from before.
                unc = max(prev_u[a - vmin] * (1.0 - f) + prev_u[b - vmin] * f, abs(ha - hb))
                if ha == NO_HORIZON or hb == NO_HORIZON:  # next to the observer only
                    unc = 0.0
                # The terrain on that line (exact: bilinear along a line of centres).
                if dup > 0.0:
                    vs = min(max(vp, vmin), vmax)
                    a2 = int(math.floor(vs))
                    b2 = min(a2 + 1, vmax)
                    f2 = vs - a2
                    ra, ca = _to_cell(q, oc, orr, k - 1, a2)
                    rb, cb = _to_cell(q, oc, orr, k - 1, b2)
                    za = elev[ra, ca]
                    zb = elev[rb, cb]
                    zs = za * (1.0 - f2) + zb * f2 if b2 != a2 else za
                    if zs != zs:
                        h = np.nan
                    else:
                        d_cross = cell * math.sqrt(dup * dup + (vp - ov) * (vp - ov))
                        s = (zs - z_obs) / d_cross
                        if s > h:  # False when h is NaN: a hole on the way stays undecided
                            unc = max(h + unc - s, 0.0)
                            h = s
                cur[j - vmin] = h
                cur_u[j - vmin] = unc
                owns = (j != k and j != -k) or q < 2
                if owns:
                    d_t = cell * math.sqrt(du * du + dv * dv)
                    zt = elev[r, c] + target_h - curv * d_t * d_t
                    margin[r, c] = zt - z_obs - h * d_t
                    slack[r, c] = unc * d_t
            prev, cur = cur, prev
            prev_u, cur_u = cur_u, prev_u


@njit(parallel=True, cache=True)
def boundary_kernel(seen, cand, out):  # pragma: no cover - numba
    """``out[r, c]`` = candidate cell with an 8-neighbour candidate of the other verdict."""
    nrows, ncols = seen.shape
    for r in prange(nrows):
        for c in range(ncols):
            out[r, c] = False
            if not cand[r, c]:
                continue
            s = seen[r, c]
            for dr in range(-1, 2):
                rr = r + dr
                if rr < 0 or rr >= nrows:
                    continue
                for dc in range(-1, 2):
                    cc = c + dc
                    if cc < 0 or cc >= ncols:
                        continue
                    if cand[rr, cc] and seen[rr, cc] != s:
                        out[r, c] = True


@njit(cache=True)
def grow_kernel(flipped, cand, checked):  # pragma: no cover - numba
    """Unchecked candidate 8-neighbours of the flat cell indices ``flipped``.

    Marks them in ``checked`` (bool, 2-D, in/out) and returns their flat indices (int64).
    """
    nrows, ncols = cand.shape
    out = np.empty(8 * len(flipped), np.int64)
    n = 0
    for k in range(len(flipped)):
        r = flipped[k] // ncols
        c = flipped[k] % ncols
        for dr in range(-1, 2):
            rr = r + dr
            if rr < 0 or rr >= nrows:
                continue
            for dc in range(-1, 2):
                cc = c + dc
                if cc < 0 or cc >= ncols:
                    continue
                if cand[rr, cc] and not checked[rr, cc]:
                    checked[rr, cc] = True
                    out[n] = rr * ncols + cc
                    n += 1
    return out[:n]


@njit(cache=True, inline="always")
def _target(elev, r, c, x_min, y_max, cell, cx, cy, target_h, curv):  # pragma: no cover
    """Target point above the centre of cell ``(r, c)``, as ``visibility.viewshed`` builds it."""
    x = x_min + (c + 0.5) * cell
    y = y_max - (r + 0.5) * cell
    horiz = math.hypot(x - cx, y - cy)
    z = (np.float64(elev[r, c]) + target_h) - horiz**2 * curv
    return x, y, z


@njit(parallel=True, cache=True)
def candidates_kernel(
    elev, x_min, y_max, cell, cx, cy, cz, target_h, curv, max_range, cand
):  # pragma: no cover - numba
    """``cand[r, c]`` = the target has data and lies at a 3-D distance in ``(0, max_range]``."""
    nrows, ncols = elev.shape
    for r in prange(nrows):
        for c in range(ncols):
            x, y, z = _target(elev, r, c, x_min, y_max, cell, cx, cy, target_h, curv)
            dx = x - cx
            dy = y - cy
            dz = z - cz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            cand[r, c] = dist == dist and dist > 0.0 and dist <= max_range


@njit(cache=True, error_model="numpy")
def _clear(
    elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, height_margin,
    cx, cy, cz, tx, ty, tz, tol_rel, tol_m, hits, base,
):  # fmt: skip  # pragma: no cover - numba
    """One exact sight line from the camera to a target: True when no terrain is crossed.

    Same ray, range and tolerance as ``core.visibility.viewshed`` passes to ``cast_rays``.
    """
    dx = tx - cx
    dy = ty - cy
    dz = tz - cz
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    reach = max(dist * (1.0 - tol_rel) - tol_m, 0.0)
    st, gx0, gy0, kx, ky, uz, t_a, t_end = _rk._prepare(
        elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, height_margin,
        cx, cy, cz, dx, dy, dz, reach,
    )  # fmt: skip
    if st != _rk.HIT:
        return True
    cnt, _ = _rk._walk(
        elev, nodes, lvl_off, lvl_shape, height_margin, gx0, gy0, cz, kx, ky, uz, t_a, t_end,
        hits, base, 1, 1, True,
    )  # fmt: skip
    return cnt == 0


@njit(parallel=True, cache=True, error_model="numpy")
def _exact_batch(
    elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, height_margin,
    cx, cy, cz, target_h, curv, tol_rel, tol_m, todo, verdict,
):  # fmt: skip  # pragma: no cover - numba
    """``verdict[i]`` = exact sight line to flat cell ``todo[i]`` is clear."""
    ncols = elev.shape[1]
    hits = np.empty(len(todo), np.float64)
    for i in prange(len(todo)):
        row = todo[i] // ncols
        col = todo[i] - row * ncols
        tx, ty, tz = _target(elev, row, col, x_min, y_max, cell, cx, cy, target_h, curv)
        verdict[i] = _clear(
            elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max,
            height_margin, cx, cy, cz, tx, ty, tz, tol_rel, tol_m, hits, i,
        )  # fmt: skip


@njit(cache=True, error_model="numpy")
def _exact_batch_serial(
    elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, height_margin,
    cx, cy, cz, target_h, curv, tol_rel, tol_m, todo, verdict,
):  # fmt: skip  # pragma: no cover - numba
    """:func:`_exact_batch` on one thread (small rounds: no thread start-up)."""
    ncols = elev.shape[1]
    hits = np.empty(len(todo), np.float64)
    for i in range(len(todo)):
        row = todo[i] // ncols
        col = todo[i] - row * ncols
        tx, ty, tz = _target(elev, row, col, x_min, y_max, cell, cx, cy, target_h, curv)
        verdict[i] = _clear(
            elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max,
            height_margin, cx, cy, cz, tx, ty, tz, tol_rel, tol_m, hits, i,
        )  # fmt: skip


@njit(cache=True, error_model="numpy")
def refine_kernel(
    elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, height_margin,
    cx, cy, cz, target_h, curv, tol_rel, tol_m, cand, seen, checked, idx,
):  # fmt: skip  # pragma: no cover - numba
    """Exact sight lines for the flat cells ``idx``, then for neighbours of every flip.

    ``seen`` (bool 2-D, in/out) holds the verdicts; ``checked`` (bool 2-D, in/out) marks
    cells already decided exactly. Each round casts its cells in parallel; the unchecked
    candidate 8-neighbours of the cells whose verdict changed form the next round, until
    a round changes nothing. Returns the number of sight lines cast.
    """
    flat_seen = seen.reshape(-1)
    total = 0
    todo = idx.copy()
    while len(todo):
        n = len(todo)
        verdict = np.empty(n, np.bool_)
        if n >= _PARALLEL_MIN:
            _exact_batch(
                elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max,
                height_margin, cx, cy, cz, target_h, curv, tol_rel, tol_m, todo, verdict,
            )  # fmt: skip
        else:
            _exact_batch_serial(
                elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max,
                height_margin, cx, cy, cz, target_h, curv, tol_rel, tol_m, todo, verdict,
            )  # fmt: skip
        total += n
        nflip = 0
        flipped = np.empty(n, np.int64)
        for i in range(n):
            if verdict[i] != flat_seen[todo[i]]:
                flat_seen[todo[i]] = verdict[i]
                flipped[nflip] = todo[i]
                nflip += 1
        todo = grow_kernel(flipped[:nflip], cand, checked)
    return total
