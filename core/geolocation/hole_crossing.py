"""Where a viewing ray passes over a DEM hole: the cell, and how far along the ray.

The caster only says that a ray crossed a hole (``crossed_nodata``); an operator needs to
know where, to judge whether the missing crossing matters (a hole strip at the far edge
of the site, or a gap in front of the target). This walks the ray over the DEM in steps
of a quarter cell, as the bilinear surface sees it: a point is over a hole where the
surface is undefined (a patch with a NaN corner) inside the hull of cell centres, and the
ray is not above the highest terrain (higher up no crossing can be missed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..terrain.dem import Dem

__all__ = ["HoleCrossing", "first_hole_crossing"]


@dataclass(frozen=True)
class HoleCrossing:
    """The first hole a ray passes over.

    Attributes
    ----------
    e_m, n_m : float
        Centre of the hole cell (site frame, m): the NaN cell nearest the ray there.
    range_m : float
        Distance along the ray (m) from its origin to where it first is over the hole.
    """

    e_m: float
    n_m: float
    range_m: float

    def describe(self) -> str:
        """``"at E .. N .. m, .. m along the ray"``."""
        return f"at E {self.e_m:.1f} N {self.n_m:.1f} m, {self.range_m:.1f} m along the ray"


def first_hole_crossing(
    dem: Dem,
    origin_enu: np.ndarray,
    direction_enu: np.ndarray,
    max_range_m: float | None = None,
) -> HoleCrossing | None:
    """The first DEM hole under a ray, or None.

    Parameters
    ----------
    dem : Dem
    origin_enu, direction_enu : ndarray, shape (3,)
        The ray (m, site frame); the direction need not be unit length.
    max_range_m : float, optional
        Walk no farther (m); default to where the ray leaves the grid.
    """
    if not dem.nodata.any():
        return None
    o = np.asarray(origin_enu, dtype=np.float64)
    d = np.asarray(direction_enu, dtype=np.float64)
    d = d / np.linalg.norm(d)
    g = dem.grid
    x0, y0, x1, y1 = g.centre_bounds
    horiz = float(np.hypot(d[0], d[1]))
    if horiz < 1e-12:
        return None
    # the walk's reach: the farthest corner of the grid, horizontally
    corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
    reach = float(np.max(np.hypot(*(corners - o[:2]).T))) / horiz
    r_max = reach if max_range_m is None else min(reach, float(max_range_m))
    step = 0.25 * g.cell_m / horiz
    r = np.arange(0.0, r_max + step, step)
    p = o[None, :] + r[:, None] * d[None, :]
    on = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    z_top = float(np.nanmax(dem.elevation))
    over = on & (p[:, 2] <= z_top) & np.isnan(dem.sample(p[:, 0], p[:, 1]))
    if not over.any():
        return None
    k = int(np.argmax(over))
    gx, gy = g.to_grid(p[k, 0], p[k, 1])
    best: tuple[float, int, int] | None = None
    for rr in (int(np.floor(gy)), int(np.floor(gy)) + 1):
        for cc in (int(np.floor(gx)), int(np.floor(gx)) + 1):
            if 0 <= rr < g.nrows and 0 <= cc < g.ncols and np.isnan(dem.elevation[rr, cc]):
                dist = float(np.hypot(cc - gx, rr - gy))
                if best is None or dist < best[0]:
                    best = (dist, rr, cc)
    if best is None:  # a NaN sample always has a NaN corner; kept for safety
        return None
    e, n = g.from_grid(np.array(best[2], dtype=np.float64), np.array(best[1], dtype=np.float64))
    return HoleCrossing(float(e), float(n), float(r[k]))
