"""Plain-numpy reference twin of the viewshed sweep kernel, for tests (small grids).

Same algorithm as :func:`~demtrack.core.visibility._viewshed_kernels.sweep_margin_kernel`, written
ring by ring with whole-ring array operations: each quadrant (east, west, south, north of
the observer's cell) is turned into a canonical ``(u, v)`` frame by transposing and
flipping the grid, the ring ``u = k`` takes its horizon from ring ``k - 1`` by linear
interpolation where each sight line crosses it, and the terrain on that line (linear
between the two centres, exact for the bilinear surface) raises the horizon.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sweep_margin_reference"]

_NO_HORIZON = -1.0e30


def _quadrant(elev: np.ndarray, q: int, oc: int, orr: int, ogx: float, ogy: float):
    """Canonical view ``E[u, v_index]`` of quadrant ``q``, its v range and observer offset."""
    if q == 0:  # east: u = col - oc, v = row - orr
        e = elev.T[oc:, :]
        return e, -orr, ogx - oc, ogy - orr
    if q == 1:  # west
        e = elev.T[oc::-1, :]
        return e, -orr, oc - ogx, ogy - orr
    if q == 2:  # south: u = row - orr, v = col - oc
        e = elev[orr:, :]
        return e, -oc, ogy - orr, ogx - oc
    e = elev[orr::-1, :]  # north
    return e, -oc, orr - ogy, ogx - oc


def _lerp(
    values: np.ndarray, v: np.ndarray, lo: int, hi: int, vmin: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear interpolation at ``v`` (clamped to ``[lo, hi]``), and the two values mixed."""
    vv = np.clip(v, lo, hi)
    a = np.floor(vv).astype(np.int64)
    b = np.minimum(a + 1, hi)
    f = vv - a
    va, vb = values[a - vmin], np.where(b != a, values[b - vmin], values[a - vmin])
    with np.errstate(invalid="ignore"):
        return va * (1.0 - f) + vb * f, va, vb


def sweep_margin_reference(
    elev: np.ndarray,
    ogx: float,
    ogy: float,
    z_obs: float,
    cell: float,
    target_h: float,
    curv: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Horizon margin (m) of every cell; see ``core.visibility._viewshed_kernels`` for the meaning.

    Returns
    -------
    margin, slack : ndarray, float64, shape of ``elev``
        ``z_target - z_obs - horizon * d`` (NaN at the observer's cell and behind holes),
        and how far (m) the interpolated horizon may be off.
    """
    elev = np.asarray(elev, dtype=np.float64)
    nrows, ncols = elev.shape
    oc = min(max(int(np.floor(ogx + 0.5)), 0), ncols - 1)
    orr = min(max(int(np.floor(ogy + 0.5)), 0), nrows - 1)
    out = np.full(elev.shape, np.nan)
    out_slack = np.zeros(elev.shape)
    for q in range(4):
        e, vmin, ou, ov = _quadrant(elev, q, oc, orr, ogx, ogy)
        vmax = vmin + e.shape[1] - 1
        m = np.full(e.shape, np.nan)
        sl = np.full(e.shape, np.nan)
        prev = np.full(e.shape[1], _NO_HORIZON)
        prev_u = np.zeros(e.shape[1])
        for k in range(1, e.shape[0]):
            lo, hi = max(-k, vmin), min(k, vmax)
            j = np.arange(lo, hi + 1)
            du, dup = k - ou, k - 1 - ou
            vp = ov + (j - ov) * dup / du
            plo, phi = max(-(k - 1), vmin), min(k - 1, vmax)
            h, ha, hb = _lerp(prev, vp, plo, phi, vmin)
            u_in, _, _ = _lerp(prev_u, vp, plo, phi, vmin)
            with np.errstate(invalid="ignore"):
                unc = np.maximum(u_in, np.abs(ha - hb))
            unc[(ha == _NO_HORIZON) | (hb == _NO_HORIZON)] = 0.0
            if dup > 0:
                zs, _, _ = _lerp(e[k - 1], vp, vmin, vmax, vmin)
                s = (zs - z_obs) / (cell * np.hypot(dup, vp - ov))
                with np.errstate(invalid="ignore"):
                    up = s > h  # False where h is NaN
                    unc = np.where(up, np.maximum(h + unc - s, 0.0), unc)
                    h = np.where(np.isnan(zs), np.nan, np.where(up, s, h))
            cur = np.full(e.shape[1], _NO_HORIZON)
            cur[j - vmin] = h
            cur_u = np.zeros(e.shape[1])
            cur_u[j - vmin] = unc
            prev, prev_u = cur, cur_u
            d_t = cell * np.hypot(du, j - ov)
            zt = e[k, j - vmin] + target_h - curv * d_t**2
            m[k, j - vmin] = zt - z_obs - h * d_t
            sl[k, j - vmin] = unc * d_t
        # Back to the grid; the diagonals belong to the east and west quadrants.
        u = np.arange(e.shape[0])[:, None]
        v = (np.arange(e.shape[1]) + vmin)[None, :]
        own = (np.abs(v) < u) | ((np.abs(v) == u) & (q < 2) & (u > 0))
        for dst, src in ((out, m), (out_slack, sl)):
            if q == 0:
                view = dst.T[oc:, :]
            elif q == 1:
                view = dst.T[oc::-1, :]
            elif q == 2:
                view = dst[orr:, :]
            else:
                view = dst[orr::-1, :]
            view[own] = src[own]
    return out, out_slack
