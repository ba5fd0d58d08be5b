"""PNG renderings of the site rasters on their own grids (the web map's base layers).

Each image covers its grid exactly: pixel (0, 0) is cell (0, 0), the north-west cell, so
a map in the site frame places it over the grid's outer bounds
(:attr:`~demtrack.core.terrain.grid.GridSpec.bounds`).
"""

from __future__ import annotations

import io
from typing import Literal

import numpy as np

from demtrack.core.terrain.dem import Dem

__all__ = ["RELIEF_KINDS", "hillshade", "png_bytes", "relief_rgba"]

ReliefKind = Literal["hillshade", "relief", "shaded-relief"]
RELIEF_KINDS: tuple[str, ...] = ("hillshade", "relief", "shaded-relief")

# Hypsometric ramp (low -> high): green lowland, yellow-brown, brown, grey-white summits.
_RAMP_POS = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
_RAMP_RGB = np.array(
    [[46, 110, 58], [122, 160, 82], [205, 190, 120], [150, 110, 80], [240, 240, 235]], float
)


def png_bytes(image: np.ndarray) -> bytes:
    """Encode ``(h, w, 3|4)`` uint8 as PNG."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def hillshade(
    elevation: np.ndarray, cell_m: float, azimuth_deg: float = 315.0, altitude_deg: float = 45.0
) -> np.ndarray:
    """Lambertian shading in [0, 1] of a north-up grid (row 0 = north); NaN where nodata.

    ``azimuth_deg`` is the sun's direction, clockwise from north; ``altitude_deg`` above the
    horizon.
    """
    z = np.asarray(elevation, dtype=np.float64)
    dz_drow, dz_dcol = np.gradient(z, cell_m)
    dz_dx, dz_dy = dz_dcol, -dz_drow  # rows run south
    az, alt = np.radians(azimuth_deg), np.radians(altitude_deg)
    sun = np.array([np.sin(az) * np.cos(alt), np.cos(az) * np.cos(alt), np.sin(alt)])
    norm = np.sqrt(dz_dx**2 + dz_dy**2 + 1.0)
    shade = (-dz_dx * sun[0] - dz_dy * sun[1] + sun[2]) / norm
    return np.clip(shade, 0.0, 1.0)


def relief_rgba(dem: Dem, kind: str = "shaded-relief") -> np.ndarray:
    """Render ``dem`` as ``(nrows, ncols, 4)`` uint8; nodata cells are transparent.

    ``kind``: ``hillshade`` (grey), ``relief`` (hypsometric colours) or
    ``shaded-relief`` (colours times shading).
    """
    z = dem.elevation.astype(np.float64)
    valid = np.isfinite(z)
    out = np.zeros((*z.shape, 4), np.uint8)
    if not valid.any():
        return out
    lo, hi = float(np.nanmin(z)), float(np.nanmax(z))
    filled = np.where(valid, z, lo)
    shade = np.nan_to_num(hillshade(filled, dem.grid.cell_m), nan=0.0)
    if kind == "hillshade":
        rgb = np.repeat((255.0 * shade)[..., None], 3, axis=-1)
    else:
        t = (filled - lo) / (hi - lo) if hi > lo else np.zeros_like(filled)
        rgb = np.stack([np.interp(t, _RAMP_POS, _RAMP_RGB[:, c]) for c in range(3)], axis=-1)
        if kind == "shaded-relief":
            rgb *= (0.35 + 0.65 * shade)[..., None]
    out[..., :3] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    out[..., 3] = np.where(valid, 255, 0).astype(np.uint8)
    return out
