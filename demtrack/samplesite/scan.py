"""Simulated airborne laser scan and coarse DEM of the sample world.

Collins et al. (1998) built their DEM from a helicopter laser survey flown along the road:
points are dense under the flight line and thin out towards the swath edge, leaving holes
in the middle of the open field, which were filled from a 30 m USGS DEM. This module
imitates both: :func:`simulate_laser_scan` flies the road centre lines and returns
first-return points (a share of the shots in tree crowns reaches the ground, giving those
cells their high variance), and :func:`coarse_dem` samples the bare earth on a 30 m grid
with a small smooth bias (about 0.2 m), as a stand-in for the USGS model.
"""

from __future__ import annotations

import numpy as np

from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

from .world import EXTENT_M, World

__all__ = ["coarse_dem", "flight_lines", "simulate_laser_scan"]

#: Half-width of the scanner's swath on the ground (m).
SWATH_HALF_M = 45.0
#: Shots per metre of flight line (across the whole swath).
SHOTS_PER_M = 1600
#: Share of shots in a crown that reach the ground through gaps in the foliage.
CROWN_PENETRATION = 0.3
#: Range noise of one laser return (m, 1 sigma).
RANGE_NOISE_M = 0.05


def flight_lines(world: World, spacing_m: float = 1.0) -> list[np.ndarray]:
    """The helicopter's tracks: each road centre line resampled every ``spacing_m``."""
    out = []
    for line in world.roads.values():
        seg = np.diff(line, axis=0)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
        t = np.arange(0.0, s[-1], spacing_m)
        out.append(np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])]))
    return out


def simulate_laser_scan(world: World, seed: int = 11) -> np.ndarray:
    """First-return laser points ``(n, 3)`` in the site frame (m).

    Each flight-line step fires shots across the swath; the across-track offset is drawn
    with a density falling off towards the swath edge (a triangular profile), so the
    middle of the field, far from every road, gets few or no points.
    """
    rng = np.random.default_rng(seed)
    chunks = []
    for track in flight_lines(world):
        heading = np.gradient(track, axis=0)
        heading /= np.linalg.norm(heading, axis=1, keepdims=True)
        normal = np.column_stack([-heading[:, 1], heading[:, 0]])
        n = len(track) * SHOTS_PER_M
        idx = rng.integers(0, len(track), n)
        along = rng.uniform(-0.5, 0.5, n)
        across = SWATH_HALF_M * (rng.uniform(0, 1, n) - rng.uniform(0, 1, n))
        xy = track[idx] + along[:, None] * heading[idx] + across[:, None] * normal[idx]
        chunks.append(xy)
    xy = np.concatenate(chunks)
    inside = (np.abs(xy) <= EXTENT_M).all(axis=1)
    x, y = xy[inside, 0], xy[inside, 1]
    z = world.surface_z(x, y)
    crown = np.isfinite(world.crown_z(x, y))
    through = crown & (rng.uniform(0, 1, len(x)) < CROWN_PENETRATION)
    z = np.where(through, world.ground_z(x, y), z)
    z = z + rng.normal(0.0, RANGE_NOISE_M, len(x))
    return np.column_stack([x, y, z])


def coarse_dem(world: World, cell_m: float = 30.0, seed: int = 5) -> Dem:
    """A USGS-like coarse bare-earth DEM covering the site with margin.

    Elevations are the true ground at the 30 m cell centres plus a smooth bias of up to
    about 0.2 m (coarse models are smoothed and offset; they know nothing of trees).
    """
    rng = np.random.default_rng(seed)
    half = EXTENT_M + 2 * cell_m
    grid = GridSpec.covering(-half, -half, half, half, cell_m)
    x, y = grid.centres()
    phase = rng.uniform(0, 2 * np.pi, 2)
    bias = 0.12 * np.sin(x / 70.0 + phase[0]) + 0.08 * np.cos(y / 90.0 + phase[1])
    return Dem(grid, world.ground_z(x, y) + bias, np.full(grid.shape, 1.0, np.float32))
