"""Write a tiled DEM as a Cloud-Optimized GeoTIFF, strip by strip, with its per-block min/max.

The layout is ``core.terrain.tiled_dem``'s. The writer asks a *cell source* for one chunk of
cells at a time (a strip of one tile's height and a few tiles' width, plus the next row and
column that the chunk's patch blocks reach into), writes it to a tiled GeoTIFF and keeps
only the block's max and min, so a 40,000 x 40,000 DEM (6.4 GB as float32) is written
holding a few tens of MB. GDAL's COG driver then rewrites that file as a COG (same tiles,
compression and predictor; internal overviews of 2x reductions down to one tile, each cell
the mean of the finite cells below it; IFDs before the data, smallest overview's tiles
first), reading and writing tile by tile under a 64 MB block cache; the block min/max and
the other ``DEMTRACK_*`` items stay in the GDAL metadata, which the COG driver copies.
Sources: an in-memory :class:`Dem` (:func:`write_dem_tiled`), any GeoTIFF read by
window (:func:`tile_geotiff`) and a smooth synthetic terrain (:func:`synth_tiled`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import DemError, InputFileError
from .dem import VERTICAL_DATUM_LOCAL, Dem
from .grid import GridSpec
from .tiled_dem import (
    GDAL_CACHE_MB,
    MINMAX_TAG,
    TILE_TAG,
    TiledDem,
    block_minmax,
    encode_minmax,
    patch_blocks,
)

__all__ = [
    "COMPRESSIONS",
    "DEFAULT_TILE",
    "CellSource",
    "synth_cells",
    "synth_tiled",
    "tile_geotiff",
    "write_dem_tiled",
    "write_tiled",
]

#: Internal tile side (cells) unless told otherwise.
DEFAULT_TILE = 512
#: Compressions the writer offers (both with the floating-point predictor).
COMPRESSIONS = ("deflate", "zstd")
#: A cell source: ``(r0, r1, c0, c1) -> float32 (bands, r1 - r0, c1 - c0)``.
CellSource = Callable[[int, int, int, int], np.ndarray]


def write_tiled(
    path: str | Path,
    grid: GridSpec,
    source: CellSource,
    *,
    bands: int = 1,
    tile: int = DEFAULT_TILE,
    compress: str = "deflate",
    crs_wkt: str | None = None,
    vertical_datum: str = VERTICAL_DATUM_LOCAL,
    chunk_tiles: int = 8,
) -> TiledDem:
    """Write ``source``'s cells over ``grid`` as a tiled DEM COG; returns it opened.

    Parameters
    ----------
    path : str or Path
        Output file (overwritten).
    grid : GridSpec
        The DEM's grid (at least 2 x 2).
    source : CellSource
        Gives the cells of a window, band 1 the elevation (m, NaN = nodata), then
        variance and count when ``bands == 3``.
    bands : {1, 3}
    tile : int
        Internal tile side and patch-block side (a power of two, 16 .. 4096).
    compress : {"deflate", "zstd"}
    chunk_tiles : int
        Tiles per chunk along a strip (memory held: about ``chunk_tiles * tile**2 * bands``
        float32 cells, plus the source's own).
    """
    if tile < 16 or tile > 4096 or tile & (tile - 1):
        raise DemError(f"tile must be a power of two from 16 to 4096, got {tile}")
    if compress not in COMPRESSIONS:
        raise DemError(f"compress must be one of {', '.join(COMPRESSIONS)}, got {compress!r}")
    if bands not in (1, 3):
        raise DemError(f"bands must be 1 or 3, got {bands}")
    nrows, ncols = grid.shape
    if nrows < 2 or ncols < 2:
        raise DemError(f"a tiled DEM needs at least 2 x 2 cells, got {nrows} x {ncols}")
    nby, nbx = patch_blocks(nrows, ncols, tile)
    minmax = np.empty((nby, nbx, 2), np.float32)
    profile: dict[str, object] = {
        "driver": "GTiff",
        "height": nrows,
        "width": ncols,
        "count": bands,
        "dtype": "float32",
        "transform": grid.transform,
        "nodata": float("nan"),
        "tiled": True,
        "blockxsize": tile,
        "blockysize": tile,
        "compress": compress,
        "predictor": 3,
        "bigtiff": "IF_SAFER",
        "num_threads": "ALL_CPUS",
    }
    if crs_wkt:
        profile["crs"] = crs_wkt
    width = tile * max(1, int(chunk_tiles))
    # Written under temporary names and renamed when complete: a failed write leaves
    # no file that looks like a tiled DEM.
    path = Path(path)
    part = path.with_name(path.name + ".partial")
    tiles = path.with_name(path.name + ".tiles.partial")
    try:
        _write(tiles, profile, grid, source, bands, tile, width, minmax, vertical_datum)
        _to_cog(tiles, part, tile, compress)
        os.replace(part, path)
    finally:
        tiles.unlink(missing_ok=True)
        part.unlink(missing_ok=True)
    return TiledDem.open(path)


def _to_cog(src: Path, dst: Path, tile: int, compress: str) -> None:
    """Rewrite the tiled GeoTIFF ``src`` as a COG at ``dst`` with GDAL's COG driver."""
    import rasterio
    from rasterio.shutil import copy

    with rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB, GDAL_NUM_THREADS="ALL_CPUS"):
        copy(
            src,
            dst,
            driver="COG",
            BLOCKSIZE=tile,
            COMPRESS=compress.upper(),
            PREDICTOR="FLOATING_POINT",
            BIGTIFF="IF_SAFER",
            OVERVIEWS="AUTO",
            RESAMPLING="AVERAGE",
            NUM_THREADS="ALL_CPUS",
        )


def _write(
    part: Path,
    profile: dict[str, object],
    grid: GridSpec,
    source: CellSource,
    bands: int,
    tile: int,
    width: int,
    minmax: np.ndarray,
    vertical_datum: str,
) -> None:
    """:func:`write_tiled`'s strip loop into ``part``."""
    import rasterio
    from rasterio.windows import Window

    nrows, ncols = grid.shape
    nby, nbx = minmax.shape[:2]
    z_lo, z_hi, holes = math.inf, -math.inf, False
    with rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB), rasterio.open(part, "w", **profile) as dst:
        for r0 in range(0, nrows, tile):
            r1 = min(r0 + tile, nrows)
            for c0 in range(0, ncols, width):
                c1 = min(c0 + width, ncols)
                # One more row and column than written: the blocks' patches reach them.
                cells = np.asarray(source(r0, min(r1 + 1, nrows), c0, min(c1 + 1, ncols)))
                cells = cells.reshape(bands, *cells.shape[-2:]).astype(np.float32, copy=False)
                dst.write(cells[:, : r1 - r0, : c1 - c0], window=Window(c0, r0, c1 - c0, r1 - r0))
                elev = cells[0]
                by = r0 // tile
                for bx in range(c0 // tile, min(-(-c1 // tile), nbx)):
                    if by < nby:
                        j = bx * tile - c0
                        minmax[by, bx] = block_minmax(elev[: tile + 1, j : j + tile + 1])
                own = elev[: r1 - r0, : c1 - c0]
                finite = own[np.isfinite(own)]
                holes = holes or finite.size < own.size
                if finite.size:
                    z_lo, z_hi = min(z_lo, float(finite.min())), max(z_hi, float(finite.max()))
        if not math.isfinite(z_lo):
            raise DemError("DEM has no finite elevation")
        info = {"tile": tile, "z_min": z_lo, "z_max": z_hi, "holes": holes}
        dst.update_tags(
            **{TILE_TAG: json.dumps(info), MINMAX_TAG: encode_minmax(minmax)},
            VERTICAL_DATUM=vertical_datum,
            CELL_VALUE_AT="centre",
        )
        for b, name in enumerate(("elevation_m", "variance_m2", "count")[:bands], start=1):
            dst.set_band_description(b, name)


def write_dem_tiled(dem: Dem, path: str | Path, **kwargs: object) -> TiledDem:
    """Write an in-memory :class:`Dem` (elevation, variance, count) as a tiled DEM.

    The bands are those of :meth:`Dem.write` (filled cells have a NaN count).
    """
    count = dem.count.astype(np.float32)
    count[dem.filled] = np.nan
    layers = (dem.elevation, dem.variance, count)

    def source(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        return np.stack([a[r0:r1, c0:c1] for a in layers])

    return write_tiled(
        path,
        dem.grid,
        source,
        bands=3,
        crs_wkt=dem.crs_wkt,
        vertical_datum=dem.vertical_datum,
        **kwargs,  # type: ignore[arg-type]
    )


def tile_geotiff(src_path: str | Path, path: str | Path, **kwargs: object) -> TiledDem:
    """Rewrite any north-up GeoTIFF DEM as a tiled DEM, window by window.

    Band 1 is the elevation (the file's nodata value becomes NaN); a file of three or
    more bands (as :meth:`Dem.write` makes) keeps bands 2 and 3 as variance and count.

    Raises
    ------
    InputFileError
        If the file cannot be read.
    """
    import rasterio
    from rasterio.errors import RasterioError
    from rasterio.windows import Window

    src_path = Path(src_path)
    if not src_path.is_file():
        raise InputFileError(f"DEM {src_path} does not exist")
    try:
        src = rasterio.open(src_path)
    except RasterioError as exc:
        raise InputFileError(f"cannot read DEM {src_path}: {exc}") from None
    with src:
        grid = GridSpec.from_transform(src.transform, src.height, src.width)
        bands = 3 if src.count >= 3 else 1
        nodata = src.nodata
        datum = src.tags().get("VERTICAL_DATUM", "unknown (not stated in file)")

        def source(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
            win = Window(c0, r0, c1 - c0, r1 - r0)
            try:
                cells = src.read(list(range(1, bands + 1)), window=win, out_dtype=np.float32)
            except RasterioError as exc:
                raise InputFileError(f"cannot read DEM {src_path}: {exc}") from None
            if nodata is not None and not np.isnan(nodata):
                cells[0][cells[0] == np.float32(nodata)] = np.nan
            return cells

        return write_tiled(
            path,
            grid,
            source,
            bands=bands,
            crs_wkt=src.crs.to_wkt() if src.crs else None,
            vertical_datum=datum,
            **kwargs,  # type: ignore[arg-type]
        )


def synth_cells(r0: int, r1: int, c0: int, c1: int, *, seed: int = 0) -> np.ndarray:
    """Elevations (m) of a smooth synthetic terrain at cells ``[r0:r1, c0:c1]`` (1, h, w).

    A pure function of the cell index: hills of a few kilometres, ridges of a few hundred
    metres and a fine texture of tens (at 1 m cells), heights about 50 .. 350 m. The same
    cell has the same value whichever window asks, so chunks agree at their seams.
    """
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, 6)
    y = np.arange(r0, r1, dtype=np.float64)[:, None]
    x = np.arange(c0, c1, dtype=np.float64)[None, :]
    z = (
        200.0
        + 90.0 * np.sin(x / 2300.0 + ph[0]) * np.cos(y / 2900.0 + ph[1])
        + 35.0 * np.sin((x + 0.6 * y) / 410.0 + ph[2])
        + 12.0 * np.sin(x / 57.0 + ph[3]) * np.sin(y / 73.0 + ph[4])
        + 3.0 * np.cos((x - y) / 13.0 + ph[5])
    )
    return z.astype(np.float32)[None]


def synth_tiled(
    path: str | Path,
    size: int,
    *,
    cell_m: float = 1.0,
    seed: int = 0,
    **kwargs: object,
) -> TiledDem:
    """Write a ``size x size`` synthetic terrain (:func:`synth_cells`) as a tiled DEM.

    The grid is centred on the local-frame origin (``x_min = -size * cell_m / 2``).
    """
    if size < 2:
        raise DemError(f"size must be at least 2 cells, got {size}")
    half = 0.5 * size * cell_m
    grid = GridSpec(-half, half, float(cell_m), size, size)

    def source(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        return synth_cells(r0, r1, c0, c1, seed=seed)

    return write_tiled(path, grid, source, **kwargs)  # type: ignore[arg-type]
