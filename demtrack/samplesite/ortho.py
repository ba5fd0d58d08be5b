"""A synthetic orthophoto of the sample world, coregistered with the site frame.

Colours are painted from the true world: grass with low-frequency texture and hill
shading, asphalt roads with a centre line, a parking lot with stall markings, roofs and
shaded tree crowns. It is what an aerial survey would give, so the operator map and the
rendered camera views drape it over the DEM.
"""

from __future__ import annotations

import numpy as np
import shapely
from rasterio import features

from demtrack.core.terrain.grid import GridSpec

from .world import EXTENT_M, PARKING, World

__all__ = ["ortho_grid", "paint_orthophoto"]

GRASS = np.array([96, 132, 62], np.float64)
FIELD = np.array([128, 150, 74], np.float64)
ASPHALT = np.array([74, 74, 78], np.float64)
LOT = np.array([92, 92, 96], np.float64)
PAINT = np.array([225, 222, 200], np.float64)
CROWN = np.array([42, 82, 38], np.float64)
ROOFS = (np.array([150, 84, 70], np.float64), np.array([118, 122, 132], np.float64))


def ortho_grid(cell_m: float = 0.25) -> GridSpec:
    """The orthophoto's grid: the whole site at ``cell_m`` per pixel."""
    return GridSpec.covering(-EXTENT_M, -EXTENT_M, EXTENT_M, EXTENT_M, cell_m)


def _value_noise(x: np.ndarray, y: np.ndarray, scale_m: float, seed: int) -> np.ndarray:
    """Smooth pseudo-random texture in [-1, 1] (sum of a few oriented sines)."""
    rng = np.random.default_rng(seed)
    out = np.zeros_like(x)
    for _ in range(6):
        ang, ph = rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)
        k = rng.uniform(0.6, 1.6) / scale_m
        out += np.sin(k * (x * np.cos(ang) + y * np.sin(ang)) + ph)
    return out / 6.0


def _mask(grid: GridSpec, geoms: list) -> np.ndarray:
    if not geoms:
        return np.zeros(grid.shape, bool)
    return features.rasterize(
        [(g, 1) for g in geoms], out_shape=grid.shape, transform=grid.transform, dtype="uint8"
    ).astype(bool)


def paint_orthophoto(world: World, grid: GridSpec, seed: int = 3) -> np.ndarray:
    """RGB image ``(nrows, ncols, 3)`` uint8 of the world seen from straight above."""
    x, y = grid.centres()
    rng = np.random.default_rng(seed)
    # Ground: grass, a lighter mown field inside the loop, hill shading.
    loop = shapely.Polygon(world.roads["loop"])
    in_field = _mask(grid, [loop.buffer(-world.road_width_m)])
    tex = _value_noise(x, y, 9.0, seed) + 0.5 * _value_noise(x, y, 2.5, seed + 1)
    rgb = np.where(in_field[..., None], FIELD, GRASS) * (1 + 0.12 * tex[..., None])
    stripes = in_field & (np.floor((x + y) / 6.0) % 2 == 0)
    rgb[stripes] *= 1.06
    zx, zy = np.gradient(world.ground_z(x, y), grid.cell_m)
    shade = np.clip(1.0 - 0.6 * (zx * 0.5 - zy * 0.5), 0.7, 1.3)
    rgb *= shade[..., None]
    # Pavement.
    px0, px1, py0, py1 = PARKING
    lot = _mask(grid, [shapely.box(px0, py0, px1, py1)])
    rgb[lot] = LOT * (1 + 0.05 * tex[lot, None])
    stalls = lot & (np.abs(((x - px0) % 3.0) - 1.5) < 0.08) & (((y - py0) % 18.0) < 5.5)
    rgb[stalls] = PAINT
    lines = [shapely.LineString(c) for c in world.roads.values()]
    road = _mask(grid, [ln.buffer(world.road_width_m / 2, cap_style="flat") for ln in lines])
    rgb[road] = ASPHALT * (1 + 0.04 * tex[road, None])
    centre = _mask(grid, [ln.buffer(0.12, cap_style="flat") for ln in lines])
    dashes = centre & (np.floor((x * 0.7 + y * 0.7) / 3.0) % 2 == 0)
    rgb[dashes] = PAINT * 0.95
    # Roofs and crowns (what the camera and the laser see from above).
    for b, colour in zip(world.buildings, ROOFS, strict=False):
        roof = (x >= b.x0) & (x <= b.x1) & (y >= b.y0) & (y <= b.y1)
        edge = roof & ((x - b.x0 < 0.6) | (b.x1 - x < 0.6) | (y - b.y0 < 0.6) | (b.y1 - y < 0.6))
        rgb[roof] = colour
        rgb[edge] = colour * 0.7
    crown = world.crown_z(x, y)
    has = np.isfinite(crown)
    cx, cy = np.gradient(np.where(has, crown, 0.0), grid.cell_m)
    leaf = 1 + 0.25 * rng.standard_normal(int(has.sum()))
    lit = np.clip(1.0 - 0.35 * (cx[has] - cy[has]), 0.55, 1.35)
    rgb[has] = CROWN * (lit * leaf)[:, None]
    return np.clip(rgb, 0, 255).astype(np.uint8)
