"""Plain-numpy reference twin of the ray caster, for tests (slow: O(patches) per ray).

Independent of the kernels' traversal: for each ray it takes *every* patch of the DEM,
computes by the slab method the stretch of range over which the ray's footprint is inside
that patch's square, and solves the ray/patch quadratic there with the textbook stable
formula (both roots, then a Newton polish), keeping roots where the ray goes from above to
below. Crossings found twice (on a shared patch edge) are merged. Status rules and the
height slab are the ones documented in ``core.raycast.cast``; the below-ground test samples the
surface with ``core.terrain.surface.bilinear_sample`` (the function behind ``Dem.sample``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..terrain.surface import bilinear_sample
from .cast import HEIGHT_MARGIN_M, RayHits, RayStatus
from .pyramid import pyramid_levels_numpy as pyramid_reference

__all__ = [
    "angular_leaves_reference",
    "cast_rays_reference",
    "next_candidate_reference",
    "pseudo_angle_reference",
    "pyramid_reference",
]

_MERGE_M = 1e-5  # crossings closer than this are one crossing found by two patches
_WINDOW_M = 1e-6  # slack when accepting a root at a patch's stretch ends


def _slab(g0: float, k: float, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range interval over which ``g0 + t k`` lies in ``[lo, hi]`` (arrays)."""
    if k == 0.0:
        inside = (g0 >= lo) & (g0 <= hi)
        return np.where(inside, -np.inf, np.inf), np.where(inside, np.inf, -np.inf)
    t1 = (lo - g0) / k
    t2 = (hi - g0) / k
    return np.minimum(t1, t2), np.maximum(t1, t2)


def _one_ray(
    e: np.ndarray,
    gx0: float,
    gy0: float,
    z0: float,
    kx: float,
    ky: float,
    uz: float,
    t_a: float,
    t_b: float,
    first: bool,
    cap: int,
) -> tuple[list[float], bool]:
    nrows, ncols = e.shape
    jgrid, igrid = np.meshgrid(np.arange(ncols - 1), np.arange(nrows - 1))
    jj = jgrid.ravel()
    ii = igrid.ravel()
    xlo, xhi = _slab(gx0, kx, jj.astype(float), jj + 1.0)
    ylo, yhi = _slab(gy0, ky, ii.astype(float), ii + 1.0)
    lo = np.maximum(np.maximum(xlo, ylo), t_a)
    hi = np.minimum(np.minimum(xhi, yhi), t_b)
    keep = lo <= hi
    ii, jj, lo, hi = ii[keep], jj[keep], lo[keep], hi[keep]
    e00, e01 = e[ii, jj], e[ii, jj + 1]
    e10, e11 = e[ii + 1, jj], e[ii + 1, jj + 1]
    hole = np.isnan(e00) | np.isnan(e01) | np.isnan(e10) | np.isnan(e11)

    # f(t) = z(t) - h(gx(t), gy(t)) as a polynomial in s = t - lo on each patch.
    u0 = gx0 + lo * kx - jj
    v0 = gy0 + lo * ky - ii
    b, c, d = e01 - e00, e10 - e00, e11 - e10 - e01 + e00
    qa = -d * kx * ky
    qb = uz - (b * kx + c * ky + d * (u0 * ky + v0 * kx))
    qc = (z0 + lo * uz) - (e00 + b * u0 + c * v0 + d * u0 * v0)
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = qb * qb - 4 * qa * qc
        sq = np.sqrt(np.where(disc > 0, disc, np.nan))
        q = -0.5 * (qb + np.where(qb >= 0, sq, -sq))
        roots = np.stack([q / qa, qc / q])  # the two roots (inf/nan where degenerate)
        for _ in range(2):  # Newton polish on the exact polynomial
            f = (qa * roots + qb) * roots + qc
            fp = 2 * qa * roots + qb
            roots = np.where(np.isfinite(roots) & (fp != 0), roots - f / fp, roots)
        fp = 2 * qa * roots + qb
        ok = (
            ~hole & (disc > 0) & (fp < 0) & (roots >= -_WINDOW_M) & (roots <= (hi - lo) + _WINDOW_M)
        )
    t_hits = np.sort((lo + np.clip(roots, 0, hi - lo))[ok])
    merged: list[float] = []
    for t in t_hits:
        if not merged or t - merged[-1] > _MERGE_M:
            merged.append(float(t))
    # The walk stops at the first hit ("first") or at the hit past the cap: holes
    # beyond that point are not reported.
    stop = np.inf
    if first and merged:
        stop = merged[0]
        merged = merged[:1]
    elif len(merged) > cap:
        stop = merged[cap]
    crossed = bool((hole & (lo <= stop)).any())
    return merged, crossed


def cast_rays_reference(
    dem: Any,
    origins: np.ndarray,
    directions: np.ndarray,
    max_range: float | np.ndarray = np.inf,
    *,
    mode: str = "all",
    max_hits: int = 256,
) -> RayHits:
    """Cast rays like :func:`core.raycast.cast.cast_rays` (same arguments, same result type).

    Inputs are assumed valid: ``dem`` has ``.grid`` and ``.elevation`` (>= 2 x 2, some
    finite), origins/directions are finite ``(n, 3)`` with non-zero directions.
    """
    grid = dem.grid
    e = np.asarray(dem.elevation, dtype=np.float32).astype(np.float64)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    rng = np.broadcast_to(np.asarray(max_range, dtype=np.float64), (n,))
    nrows, ncols = e.shape
    z_min, z_max = float(np.nanmin(e)), float(np.nanmax(e))
    first = mode == "first"
    cap = 1 if first else max_hits
    status = np.empty(n, np.int8)
    crossed = np.zeros(n, bool)
    truncated = np.zeros(n, bool)
    per_ray: list[list[float]] = []
    units = dirs / np.linalg.norm(dirs, axis=1)[:, None]
    for i in range(n):
        hits: list[float] = []
        ux, uy, uz = units[i]
        gx0, gy0 = grid.to_grid(o[i, 0], o[i, 1])
        gx0, gy0, z0 = float(gx0), float(gy0), float(o[i, 2])
        kx, ky = ux / grid.cell_m, -uy / grid.cell_m
        ax_lo, ax_hi = _slab(gx0, kx, np.array(0.0), np.array(ncols - 1.0))
        ay_lo, ay_hi = _slab(gy0, ky, np.array(0.0), np.array(nrows - 1.0))
        t_lo = max(0.0, float(ax_lo), float(ay_lo))
        t_hi = min(float(rng[i]), float(ax_hi), float(ay_hi))
        h0 = bilinear_sample(e, gx0, gy0)
        if not t_lo <= t_hi:
            status[i] = RayStatus.OUTSIDE
        elif uz >= 0 and z0 >= z_max:
            status[i] = RayStatus.UPWARD
        elif np.isfinite(h0) and z0 < h0:
            status[i] = RayStatus.BELOW_GROUND
        else:
            zs_lo, zs_hi = _slab(
                z0, uz, np.array(z_min - HEIGHT_MARGIN_M), np.array(z_max + HEIGHT_MARGIN_M)
            )
            t_lo, t_hi = max(t_lo, float(zs_lo)), min(t_hi, float(zs_hi))
            if t_lo <= t_hi:
                hits, crossed[i] = _one_ray(e, gx0, gy0, z0, kx, ky, uz, t_lo, t_hi, first, cap)
            if len(hits) > cap:
                truncated[i] = True
                hits = hits[:cap]
            status[i] = RayStatus.HIT if hits else RayStatus.MISS
        per_ray.append(hits)
    counts = np.array([len(h) for h in per_ray], np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    range_m = np.array([t for h in per_ray for t in h], np.float64)
    ray_of_hit = np.repeat(np.arange(n), counts)
    points = o[ray_of_hit] + range_m[:, None] * units[ray_of_hit]
    return RayHits(offsets, range_m, points.reshape(-1, 3), status, crossed, truncated)


# ---------------------------------------------------------------------- angular index
def pseudo_angle_reference(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Diamond angle in ``[0, 4)`` of grid-frame offsets (arrays), as ``_angular_kernels``."""
    dx = np.asarray(dx, np.float64)
    dy = np.asarray(dy, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(
            dy >= 0.0,
            np.where(dx >= 0.0, dy / (dx + dy), 1.0 + (-dx) / (dy - dx)),
            np.where(dx < 0.0, 2.0 + (-dy) / (-dx - dy), 3.0 + dx / (dx - dy)),
        )


def angular_leaves_reference(
    elevation: np.ndarray,
    gxo: float,
    gyo: float,
    oz: float,
    n_az: int,
    d_rho: float,
    n_r: int,
    margin: float = HEIGHT_MARGIN_M,
) -> np.ndarray:
    """Leaf bounds of the angular index of origin ``(gxo, gyo, oz)``, every azimuth bin.

    Plain numpy over every patch: its range span (nearest point, farthest corner), its
    pseudo-angle span (corner extremes; split at the ``+gx`` cut; the whole circle for
    the patch holding the origin), widened by the kernels' slacks; heights max/min into
    each bin touched, then divided by the bin's near or far range as the sign demands.

    Returns
    -------
    ndarray, float32, shape (n_az, n_r, 2)
        ``[..., 0]`` max and ``[..., 1]`` min angle (m per cell); empty bins
        ``(-inf, +inf)``, bins touching a hole ``(+inf, -inf)``.
    """
    from ._angular_index_kernels import P_EPS, RHO_EPS  # the same slacks as the kernels

    e = np.asarray(elevation, np.float32)
    nrows, ncols = e.shape
    igrid, jgrid = np.meshgrid(np.arange(nrows - 1), np.arange(ncols - 1), indexing="ij")
    ii, jj = igrid.ravel(), jgrid.ravel()
    corners = np.stack([e[ii, jj], e[ii, jj + 1], e[ii + 1, jj], e[ii + 1, jj + 1]])
    hole = np.isnan(corners).any(axis=0)
    hi = np.where(hole, np.inf, np.nanmax(np.where(hole, 0, corners), axis=0))
    lo = np.where(hole, -np.inf, np.nanmin(np.where(hole, 0, corners), axis=0))
    x0, y0 = jj - gxo, ii - gyo
    x1, y1 = x0 + 1.0, y0 + 1.0
    cx, cy = np.clip(0.0, x0, x1), np.clip(0.0, y0, y1)
    rmin = np.sqrt(cx * cx + cy * cy)
    rmax = np.sqrt(np.maximum(x0 * x0, x1 * x1) + np.maximum(y0 * y0, y1 * y1))
    blo = np.maximum(0, np.floor((rmin - RHO_EPS) / d_rho)).astype(int)
    bhi = np.minimum(n_r - 1, np.floor((rmax + RHO_EPS) / d_rho)).astype(int)
    p = pseudo_angle_reference(np.stack([x0, x1, x0, x1]), np.stack([y0, y0, y1, y1]))
    wrap = (x0 > 0) & (y0 < 0) & (y1 >= 0)
    plo = np.where(wrap, np.minimum(p[0], p[1]) - 4.0, p.min(axis=0))
    phi = np.where(wrap, np.maximum(p[2], p[3]), p.max(axis=0))
    alo = np.floor((plo - P_EPS) * (n_az / 4.0)).astype(int)
    ahi = np.floor((phi + P_EPS) * (n_az / 4.0)).astype(int)
    full = ((x0 <= 0) & (x1 >= 0) & (y0 <= 0) & (y1 >= 0)) | (ahi - alo >= n_az)
    alo = np.where(full, 0, alo)
    ahi = np.where(full, n_az - 1, ahi)
    zmax = np.full((n_az, n_r), -np.inf)
    zmin = np.full((n_az, n_r), np.inf)
    for k in range(len(ii)):
        if blo[k] > bhi[k]:
            continue
        az = np.arange(alo[k], ahi[k] + 1) % n_az
        sl = np.ix_(az, np.arange(blo[k], bhi[k] + 1))
        zmax[sl] = np.maximum(zmax[sl], hi[k])
        zmin[sl] = np.minimum(zmin[sl], lo[k])
    r_lo = np.arange(n_r) * d_rho
    r_hi = r_lo + d_rho
    with np.errstate(divide="ignore", invalid="ignore"):
        num = zmax + margin - oz
        amax = np.where(num >= 0, np.where(r_lo > 0, num / r_lo, np.inf), num / r_hi)
        num = zmin - margin - oz
        amin = np.where(num >= 0, num / r_hi, np.where(r_lo > 0, num / r_lo, -np.inf))
    empty = zmax == -np.inf
    amax = np.where(empty, -np.inf, amax)
    amin = np.where(empty, np.inf, amin)
    # Outward rounding to float32.
    fmax = amax.astype(np.float32)
    fmax = np.where(fmax.astype(np.float64) < amax, np.nextafter(fmax, np.float32(np.inf)), fmax)
    fmin = amin.astype(np.float32)
    fmin = np.where(fmin.astype(np.float64) > amin, np.nextafter(fmin, np.float32(-np.inf)), fmin)
    return np.stack([fmax, fmin], axis=-1).astype(np.float32)


def next_candidate_reference(leaves: np.ndarray, b: int, b_end: int, s: float) -> int:
    """First bin in ``[b, b_end]`` of ``leaves`` ((n_r, 2) max, min) holding ``s``.

    ``b_end + 1`` when there is none; a linear scan.
    """
    ok = (leaves[b : b_end + 1, 0] >= s) & (leaves[b : b_end + 1, 1] <= s)
    hit = np.flatnonzero(ok)
    return int(b + hit[0]) if len(hit) else int(b_end + 1)
