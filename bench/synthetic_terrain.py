"""Deterministic synthetic site for benchmarks: hills, flat-roofed buildings and trees.

Everything is generated from one seed with ``np.random.default_rng`` so every run (and
every engine in a run) sees the same DEM and the same rays. Sizes are in cells; the
default cell is 0.5 m as in the VSAM site DEM.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from demtrack.core.terrain.grid import GridSpec
from demtrack.core.terrain.surface import bilinear_sample

__all__ = ["SyntheticDem", "camera_rays", "incoherent_rays", "synthetic_dem"]


@dataclass(frozen=True, eq=False)
class SyntheticDem:
    """The minimal DEM interface the ray caster needs (``grid`` + ``elevation``)."""

    grid: GridSpec
    elevation: np.ndarray


def synthetic_dem(size: int = 2000, cell_m: float = 0.5, seed: int = 0) -> SyntheticDem:
    """Build a ``size x size`` DEM of rolling hills with buildings and trees.

    Parameters
    ----------
    size : int
        Rows and columns (>= 8).
    cell_m : float
        Cell edge (m).
    seed : int
        Seed of the generator; the same seed gives the same DEM.

    Returns
    -------
    SyntheticDem
        Grid with its north-west corner at (0, size * cell_m); float32 elevations (m),
        no nodata.
    """
    rng = np.random.default_rng(seed)
    extent = size * cell_m
    grid = GridSpec(0.0, extent, cell_m, size, size)
    c = (np.arange(size) + 0.5) * cell_m  # centre coordinates along both axes
    x = c[None, :]
    y = (extent - c)[:, None]
    # Hills: a tilted plane plus separable Gaussian bumps (cheap outer products).
    z = 0.01 * x + 0.005 * y
    for _ in range(24):
        cx, cy = rng.uniform(0, extent, 2)
        sx, sy = rng.uniform(0.05, 0.25, 2) * extent
        amp = rng.uniform(-8.0, 25.0)
        z = z + amp * np.exp(-0.5 * ((x - cx) / sx) ** 2) * np.exp(-0.5 * ((y - cy) / sy) ** 2)
    z = z.astype(np.float32)
    ground = z.copy()
    occupied = np.zeros((size, size), bool)

    # Buildings: rotated rectangles with a flat roof above the highest ground they cover.
    n_buildings = max(1, int(150 * (size / 2000) ** 2))
    for _ in range(n_buildings):
        w, h = rng.uniform(8.0, 40.0, 2)
        ang = rng.uniform(0, np.pi)
        half = int(np.ceil(0.5 * np.hypot(w, h) / cell_m)) + 1
        r0, c0 = rng.integers(half, max(half + 1, size - half), 2)
        rs = slice(max(0, r0 - half), min(size, r0 + half + 1))
        cs = slice(max(0, c0 - half), min(size, c0 + half + 1))
        dx = (np.arange(cs.start, cs.stop) - c0)[None, :] * cell_m
        dy = (np.arange(rs.start, rs.stop) - r0)[:, None] * cell_m
        a = np.abs(dx * np.cos(ang) + dy * np.sin(ang)) <= w / 2
        b = np.abs(-dx * np.sin(ang) + dy * np.cos(ang)) <= h / 2
        mask = a & b
        if not mask.any():
            continue
        roof = ground[rs, cs][mask].max() + rng.uniform(4.0, 20.0)
        z[rs, cs][mask] = roof
        occupied[rs, cs] |= mask

    # Trees: ellipsoidal crowns on open ground.
    n_trees = max(1, int(4000 * (size / 2000) ** 2))
    for _ in range(n_trees):
        radius = rng.uniform(1.5, 4.0)
        height = rng.uniform(4.0, 15.0)
        k = int(np.ceil(radius / cell_m))
        r0, c0 = rng.integers(k, max(k + 1, size - k), 2)
        if occupied[r0, c0]:
            continue
        rs = slice(max(0, r0 - k), min(size, r0 + k + 1))
        cs = slice(max(0, c0 - k), min(size, c0 + k + 1))
        dx = (np.arange(cs.start, cs.stop) - c0)[None, :] * cell_m
        dy = (np.arange(rs.start, rs.stop) - r0)[:, None] * cell_m
        q = 1.0 - (dx**2 + dy**2) / radius**2
        crown = ground[r0, c0] + height * np.sqrt(np.clip(q, 0.0, None))
        free = (q > 0) & ~occupied[rs, cs]
        z[rs, cs] = np.where(free, np.maximum(z[rs, cs], crown), z[rs, cs])
    return SyntheticDem(grid, np.ascontiguousarray(z, dtype=np.float32))


def _surface(dem: SyntheticDem, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Terrain height (m) under x, y, clamped into the domain of the surface."""
    gx, gy = dem.grid.to_grid(x, y)
    nrows, ncols = dem.elevation.shape
    return bilinear_sample(dem.elevation, np.clip(gx, 0, ncols - 1), np.clip(gy, 0, nrows - 1))


def camera_rays(
    dem: SyntheticDem, n: int, n_cameras: int = 12, seed: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel rays of pinhole cameras on masts looking down onto the terrain.

    Each camera stands in the inner 80 % of the site on an 8-25 m mast, looks along a
    random azimuth tilted 12-35 degrees down with a 50-80 degree horizontal field of view
    and a 4:3 image; its share of ``n`` rays is a row-major grid of pixel rays
    (OpenCV camera frame: x right, y down, z forward).

    Returns
    -------
    origins, directions : ndarray, float64, shape (n, 3)
        Local frame (x east, y north, z up), directions unit length.
    """
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = dem.grid.bounds
    per = np.diff(np.linspace(0, n, n_cameras + 1).round().astype(int))
    origins, dirs = [], []
    for m in per:
        cx = rng.uniform(x0 + 0.1 * (x1 - x0), x1 - 0.1 * (x1 - x0))
        cy = rng.uniform(y0 + 0.1 * (y1 - y0), y1 - 0.1 * (y1 - y0))
        cz = _surface(dem, np.array([cx]), np.array([cy]))[0] + rng.uniform(8, 25)
        az = rng.uniform(0, 2 * np.pi)
        tilt = -np.radians(rng.uniform(12, 35))
        hfov = np.radians(rng.uniform(50, 80))
        width = max(1, int(np.ceil(np.sqrt(m * 4 / 3))))
        height = max(1, int(np.ceil(m / width)))
        f = 0.5 * width / np.tan(0.5 * hfov)
        u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
        d_cam = np.column_stack(
            [
                (u.ravel() - 0.5 * (width - 1)) / f,
                (v.ravel() - 0.5 * (height - 1)) / f,
                np.ones(u.size),
            ]
        )[:m]
        fwd = np.array([np.sin(az) * np.cos(tilt), np.cos(az) * np.cos(tilt), np.sin(tilt)])
        right = np.array([np.cos(az), -np.sin(az), 0.0])
        down = np.cross(fwd, right)
        R_world_cam = np.column_stack([right, down, fwd])
        d = d_cam @ R_world_cam.T
        dirs.append(d / np.linalg.norm(d, axis=1)[:, None])
        origins.append(np.tile([cx, cy, cz], (m, 1)))
    return np.vstack(origins), np.vstack(dirs)


def incoherent_rays(dem: SyntheticDem, n: int, seed: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Random rays: origins 2-60 m above the terrain, directions 5-85 degrees downwards.

    Returns
    -------
    origins, directions : ndarray, float64, shape (n, 3)
        Local frame, directions unit length; azimuths uniform.
    """
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = dem.grid.bounds
    x = rng.uniform(x0, x1, n)
    y = rng.uniform(y0, y1, n)
    z = _surface(dem, x, y) + rng.uniform(2, 60, n)
    az = rng.uniform(0, 2 * np.pi, n)
    el = -np.radians(rng.uniform(5, 85, n))
    d = np.column_stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    return np.column_stack([x, y, z]), d
