"""A DEM larger than memory: a tiled, compressed GeoTIFF read by window, with its tile min/max.

The file is a tiled GeoTIFF (internal square tiles of ``tile`` cells, a power of two;
DEFLATE or ZSTD with the floating-point predictor; BigTIFF when large), written as a
Cloud-Optimized GeoTIFF with internal overviews (2x reductions, each cell the mean of the
finite cells below it, down to one tile; any overviews a file has are accepted), band 1 the
elevation (m, local-frame Z, NaN = nodata) and, when written from a :class:`Dem`, bands 2
and 3 its variance and count as :meth:`Dem.write` stores them. ``core.terrain.tiled_write``
writes it strip by strip without ever holding the raster.

Next to the cells the file carries, in its GDAL metadata, the max and min elevation of each
*patch block*: block ``(by, bx)`` is the ``tile x tile`` patches (squares between four cell
centres, ``core.raycast.pyramid``) of rows ``by*tile .. by*tile + tile`` and columns
``bx*tile .. bx*tile + tile`` of cell centres, so it reads one row and one column of the next
tile. A block with a nodata cell is stored as ``(+inf, -inf)``, as the pyramid stores holes.
These are level ``log2(tile)`` of the DEM's min/max pyramid: the coarse grid the tiled ray
caster (``core.raycast.tiled_cast``) keeps in memory to skip blocks a ray passes above.

:class:`TiledDem` opens such a file and reads windows and blocks (one dataset handle per
thread, so reads from several threads never share GDAL state); :meth:`TiledDem.window_dem`
reads a window into a plain :class:`Dem`. Reads of cells are always of the full-resolution
image; :meth:`TiledDem.read_overview` reads an overview (a coarse look at the whole DEM).
"""

from __future__ import annotations

import base64
import io
import json
import threading
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DemError, InputFileError
from .dem import VERTICAL_DATUM_LOCAL, Dem
from .grid import GridSpec
from .surface import bilinear_sample

__all__ = [
    "MINMAX_TAG",
    "TILE_TAG",
    "TiledDem",
    "block_minmax",
    "decode_minmax",
    "encode_minmax",
    "patch_blocks",
]

#: Metadata key of the per-block (max, min) grid (base64 of a zlib-compressed ``.npy``).
MINMAX_TAG = "DEMTRACK_BLOCK_MINMAX"
#: Metadata key of the tile description: JSON ``{"tile", "z_min", "z_max", "holes"}``.
TILE_TAG = "DEMTRACK_TILE"
#: GDAL's block cache while a tiled DEM is read (MiB): reads are of one tile and its
#: neighbours' edge rows, so a small cache keeps those without growing past the budget.
GDAL_CACHE_MB = 64


def patch_blocks(nrows: int, ncols: int, tile: int) -> tuple[int, int]:
    """Number of patch blocks ``(rows, cols)`` of a ``nrows x ncols`` grid."""
    return (max(1, -(-(nrows - 1) // tile)), max(1, -(-(ncols - 1) // tile)))


def block_minmax(cells: np.ndarray) -> tuple[float, float]:
    """(max, min) of the patches over ``cells`` (one block with its next row and column).

    ``(+inf, -inf)`` when a cell is NaN, as ``core.raycast.pyramid`` marks holes.
    """
    if np.isnan(cells).any():
        return float("inf"), float("-inf")
    return float(cells.max()), float(cells.min())


def encode_minmax(minmax: np.ndarray) -> str:
    """The ``(rows, cols, 2)`` float32 block grid as a metadata string."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(minmax, np.float32), allow_pickle=False)
    return base64.b64encode(zlib.compress(buf.getvalue(), 6)).decode("ascii")


def decode_minmax(text: str) -> np.ndarray:
    """Inverse of :func:`encode_minmax`."""
    raw = zlib.decompress(base64.b64decode(text.encode("ascii")))
    return np.load(io.BytesIO(raw), allow_pickle=False)


@dataclass(frozen=True, eq=False)
class TiledDem:
    """A tiled DEM GeoTIFF opened for windowed reads.

    Parameters
    ----------
    path : Path
        The file.
    grid : GridSpec
        Its georeferencing (site frame, m).
    tile : int
        Side of a patch block (cells; a power of two, the file's internal tile side).
    minmax : ndarray, float32, shape (block_rows, block_cols, 2)
        Per patch block ``[..., 0]`` max and ``[..., 1]`` min elevation (m); holes
        ``(+inf, -inf)``.
    z_min, z_max : float
        Lowest and highest finite elevation (m).
    holes : bool
        Whether any cell is nodata.
    bands : int
        Bands in the file (3 when variance and count are stored).
    crs_wkt : str or None
        WKT of the grid's 2-D CRS, if stated.
    vertical_datum : str
        What the elevations are measured from.
    overviews : tuple of int
        Decimation factors of the file's internal overviews (``(2, 4, ...)``; empty when
        it has none).
    """

    path: Path
    grid: GridSpec
    tile: int
    minmax: np.ndarray
    z_min: float
    z_max: float
    holes: bool
    bands: int
    crs_wkt: str | None = None
    vertical_datum: str = VERTICAL_DATUM_LOCAL
    overviews: tuple[int, ...] = ()
    _local: threading.local = field(default_factory=threading.local, repr=False)

    @classmethod
    def open(cls, path: str | Path) -> TiledDem:
        """Open a file written by ``core.terrain.tiled_write``.

        Raises
        ------
        InputFileError
            If the file cannot be read or lacks the block min/max (not written by
            ``demtrack dem tile`` / ``dem synth``).
        """
        import rasterio
        from rasterio.errors import RasterioError

        path = Path(path)
        if not path.is_file():
            raise InputFileError(f"tiled DEM {path} does not exist")
        try:
            with rasterio.open(path) as src:
                tags = src.tags()
                grid = GridSpec.from_transform(src.transform, src.height, src.width)
                crs_wkt = src.crs.to_wkt() if src.crs else None
                bands = int(src.count)
                block = src.block_shapes[0]
                overviews = tuple(int(f) for f in src.overviews(1))
        except RasterioError as exc:
            raise InputFileError(f"cannot read tiled DEM {path}: {exc}") from None
        if MINMAX_TAG not in tags or TILE_TAG not in tags:
            raise InputFileError(
                f"{path} has no block min/max: write it with 'demtrack dem tile' first"
            )
        try:
            info = json.loads(tags[TILE_TAG])
            minmax = decode_minmax(tags[MINMAX_TAG])
            tile = int(info["tile"])
        except (ValueError, KeyError, TypeError, zlib.error) as exc:
            raise InputFileError(f"{path}: damaged block min/max metadata ({exc})") from None
        if minmax.shape != (*patch_blocks(grid.nrows, grid.ncols, tile), 2):
            raise InputFileError(f"{path}: block min/max of shape {minmax.shape} does not fit")
        if block != (tile, tile):
            raise InputFileError(f"{path}: internal tiles {block} are not {tile} x {tile}")
        minmax.setflags(write=False)
        datum = tags.get("VERTICAL_DATUM", "unknown (not stated in file)")
        return cls(
            path,
            grid,
            tile,
            minmax,
            float(info["z_min"]),
            float(info["z_max"]),
            bool(info["holes"]),
            bands,
            crs_wkt,
            datum,
            overviews,
        )

    @property
    def nbytes_cells(self) -> int:
        """Size of the elevation band decoded (bytes): what an in-memory DEM would hold."""
        return self.grid.nrows * self.grid.ncols * 4

    def _dataset(self) -> Any:
        """The calling thread's open dataset (GDAL handles must not be shared between threads)."""
        ds = getattr(self._local, "ds", None)
        if ds is None:
            import rasterio

            self._local.env = rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB)
            self._local.env.__enter__()
            ds = rasterio.open(self.path)
            self._local.ds = ds
        return ds

    def read_cells(self, r0: int, r1: int, c0: int, c1: int, band: int = 1) -> np.ndarray:
        """Cells ``[r0:r1, c0:c1]`` of ``band`` (float32; clipped windows are not allowed)."""
        from rasterio.windows import Window

        g = self.grid
        if not (0 <= r0 < r1 <= g.nrows and 0 <= c0 < c1 <= g.ncols):
            raise DemError(f"window rows {r0}:{r1}, cols {c0}:{c1} outside {g.nrows} x {g.ncols}")
        ds = self._dataset()
        out = ds.read(band, window=Window(c0, r0, c1 - c0, r1 - r0), out_dtype=np.float32)
        return np.ascontiguousarray(out, np.float32)

    def read_block(self, by: int, bx: int, out: np.ndarray) -> tuple[int, int]:
        """Read patch block ``(by, bx)`` with a one-cell halo into ``out``.

        ``out`` (float32, ``(tile + 2, tile + 2)``) receives the cells of rows
        ``by*tile - 1 .. by*tile + tile`` and the same columns (row ``r`` at
        ``out[r - by*tile + 1]``); parts outside the grid are NaN. Returns the shape
        ``(rows, cols)`` of the block's own cells (``out[1:1+rows, 1:1+cols]``).
        """
        g, t = self.grid, self.tile
        r_lo, c_lo = by * t - 1, bx * t - 1
        r0, c0 = max(r_lo, 0), max(c_lo, 0)
        r1, c1 = min(by * t + t + 1, g.nrows), min(bx * t + t + 1, g.ncols)
        out.fill(np.nan)
        out[r0 - r_lo : r1 - r_lo, c0 - c_lo : c1 - c_lo] = self.read_cells(r0, r1, c0, c1)
        return r1 - by * t, c1 - bx * t

    def read_overview(self, level: int, band: int = 1) -> np.ndarray:
        """The whole of overview ``level`` (0 = the first, ``overviews[level]`` times coarser).

        Float32, about ``nrows / f x ncols / f`` for factor ``f`` (GDAL rounds the sizes
        down); NaN = nodata.
        """
        import rasterio

        if not 0 <= level < len(self.overviews):
            raise DemError(f"{self.path} has {len(self.overviews)} overviews, not a level {level}")
        with (
            rasterio.Env(GDAL_CACHEMAX=GDAL_CACHE_MB),
            rasterio.open(self.path, overview_level=level) as ds,
        ):
            return np.ascontiguousarray(ds.read(band, out_dtype=np.float32), np.float32)

    def window_dem(self, r0: int, r1: int, c0: int, c1: int) -> Dem:
        """Cells ``[r0:r1, c0:c1]`` as an in-memory :class:`Dem` on their own grid."""
        g = self.grid
        elev = self.read_cells(r0, r1, c0, c1)
        if self.bands >= 3:
            var = self.read_cells(r0, r1, c0, c1, band=2)
            cnt_f = self.read_cells(r0, r1, c0, c1, band=3)
            filled = np.isnan(cnt_f) & ~np.isnan(elev)
            cnt = np.nan_to_num(cnt_f, nan=0.0).astype(np.int32)
        else:
            var = np.zeros_like(elev)
            cnt = np.where(np.isnan(elev), 0, 1).astype(np.int32)
            filled = None
        sub = GridSpec(g.x_min + c0 * g.cell_m, g.y_max - r0 * g.cell_m, g.cell_m, r1 - r0, c1 - c0)
        return Dem(sub, elev, var, cnt, filled, self.crs_wkt, self.vertical_datum)

    def sample(self, x: np.ndarray, y: np.ndarray, band: int = 1) -> np.ndarray:
        """Bilinear surface at points (m): as :meth:`Dem.sample`, reading only their blocks.

        NaN outside the hull of cell centres or over a hole. Points are grouped by the
        patch block they fall in; each block's cells are read once per call.
        """
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        out = np.full(x.shape, np.nan)
        g, t = self.grid, self.tile
        gx, gy = g.to_grid(x, y)
        ok = np.isfinite(gx) & np.isfinite(gy)
        ok &= (gx >= 0) & (gx <= g.ncols - 1) & (gy >= 0) & (gy <= g.nrows - 1)
        idx = np.flatnonzero(ok)
        if not len(idx):
            return out
        gxs, gys = gx.ravel()[idx], gy.ravel()[idx]
        # The patch a point is in (the last row/column of centres belongs to the one before).
        ix = np.minimum(np.floor(gxs).astype(np.int64), g.ncols - 2)
        iy = np.minimum(np.floor(gys).astype(np.int64), g.nrows - 2)
        key = (iy // t) * (g.ncols // t + 1) + ix // t
        flat = out.reshape(-1)
        for k in np.unique(key).tolist():
            sel = np.flatnonzero(key == k)
            r0, c0 = int(iy[sel[0]] // t * t), int(ix[sel[0]] // t * t)
            cells = self.read_cells(
                r0, min(r0 + t + 1, g.nrows), c0, min(c0 + t + 1, g.ncols), band
            )
            # Shifting by whole cells is exact in float64, so the values are Dem.sample's.
            flat[idx[sel]] = bilinear_sample(cells, gxs[sel] - c0, gys[sel] - r0)
        return out

    def sample_variance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear per-cell variance (m^2) at points, as :meth:`Dem.sample_variance`.

        Zero where the file stores no variance band (as :meth:`Dem.read` assumes).
        """
        if self.bands < 3:
            return np.where(np.isnan(self.sample(x, y)), np.nan, 0.0)
        return self.sample(x, y, band=2)

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slope ``(dz/dx, dz/dy)`` of the surface, as :meth:`Dem.gradient` (its code)."""
        return Dem.gradient(self, x, y)  # type: ignore[arg-type]  # needs .grid and .sample

    def close(self) -> None:
        """Close this thread's dataset handle (others close when their threads end)."""
        ds = getattr(self._local, "ds", None)
        if ds is not None:
            ds.close()
            self._local.env.__exit__(None, None, None)
            self._local.ds = None
