"""Orthophoto GeoTIFFs on the site frame: RGB uint8, north-up, cell value at the centre."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputFileError
from ..terrain.grid import GridSpec

__all__ = ["read_orthophoto", "write_orthophoto"]


def write_orthophoto(
    path: str | Path, rgb: np.ndarray, grid: GridSpec, crs_wkt: str | None = None
) -> None:
    """Write ``rgb`` (``(nrows, ncols, 3)`` uint8 on ``grid``) as a tiled RGB GeoTIFF."""
    import rasterio

    rgb = np.asarray(rgb)
    if rgb.shape != (*grid.shape, 3) or rgb.dtype != np.uint8:
        raise InputFileError(
            f"orthophoto must be uint8 with shape {(*grid.shape, 3)}, got {rgb.dtype} {rgb.shape}"
        )
    profile = {
        "driver": "GTiff",
        "height": grid.nrows,
        "width": grid.ncols,
        "count": 3,
        "dtype": "uint8",
        "transform": grid.transform,
        "photometric": "RGB",
        "compress": "deflate",
    }
    if crs_wkt:
        profile["crs"] = crs_wkt
    with rasterio.open(Path(path), "w", **profile) as dst:
        dst.write(np.moveaxis(rgb, -1, 0))


def read_orthophoto(path: str | Path) -> tuple[np.ndarray, GridSpec]:
    """Read an orthophoto: ``(rgb (nrows, ncols, 3) uint8, grid)``; one band reads as grey."""
    import rasterio
    from rasterio.errors import RasterioIOError

    try:
        with rasterio.open(Path(path)) as src:
            bands = src.read()
            grid = GridSpec.from_transform(src.transform, src.height, src.width)
    except RasterioIOError as exc:
        raise InputFileError(f"cannot read orthophoto {path}: {exc}") from None
    if bands.dtype != np.uint8:
        raise InputFileError(f"orthophoto {path} must be 8-bit, got {bands.dtype}")
    rgb = np.repeat(bands[:1], 3, axis=0) if len(bands) < 3 else bands[:3]
    return np.ascontiguousarray(np.moveaxis(rgb, 0, -1)), grid
