"""Terrain from GeoTIFF DEM/DSM tiles in any CRS, mosaicked onto a site-frame grid.

Each target cell centre of the site grid is carried exactly into the tiles' CRS and the
tiles are sampled there (:func:`~demtrack.core.terrain.crs_import.warp_to_local`): positions are
transformed, grids are never rotated, so meridian convergence, grid scale factor and the
earth's curvature are all accounted for, and the heights' unit (metre, US survey foot, ...)
is converted.

Mosaicking. Tiles that share a CRS, a pixel size and a pixel lattice (the usual case: one
product cut into tiles) are first merged into one source raster, so the bilinear surface
runs across their seams; a seam between two tiles is otherwise a strip one source cell
wide that neither tile's hull of cell centres covers. Where tiles overlap, the tile listed
first wins. Tiles of different lattices or CRSs are warped separately, and again the first
listed wins cell by cell. Cells still empty are filled, when a coarse DEM is given, by
bilinear interpolation of it (the VSAM report's 30 m fallback), and are marked as filled.

Heights: the tiles' heights ``H`` become ellipsoidal as ``h = H * z_unit_m + N(lat, lon)``
with the site's geoid (evaluated at each cell; a constant ``N``, or 0 for ellipsoidal
sources), then local-frame Z.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from affine import Affine

from ..errors import CrsError, DemError, InputFileError
from ..geo.geodesy import LocalFrame, as_crs, cached_transformer, horizontal_crs, z_unit_m_of
from ..geo.geoid import GeoidModel, as_geoid
from .crs_import import source_window, unit_m_from_tag, warp_to_local
from .dem import Dem
from .grid import GridSpec

__all__ = [
    "DemImport",
    "RasterInfo",
    "footprint_bounds_local",
    "crop_import",
    "grid_over",
    "import_dem",
    "largest_data_rectangle",
    "native_cell_m",
    "raster_outline_lonlat",
    "read_raster_info",
    "sub_grid",
    "suggest_frame",
]

_RECT_EXACT_SIDE = 256  # largest_data_rectangle: exact search up to this many cells a side
_LATTICE_TOL_PX = 1e-6  # tiles whose origins differ by a whole number of pixels to this


@dataclass(frozen=True, eq=False)
class RasterInfo:
    """Georeferencing of one raster file, read from its header.

    Attributes
    ----------
    path : Path
    crs_wkt : str
        The file's CRS (horizontal, or compound with a vertical part).
    transform : Affine
        GDAL affine (maps pixel corners).
    shape : (rows, cols)
    count : int
        Number of bands.
    band_unit_m : float or None
        Metres per unit of band 1 from its unit tag, None when untagged.
    dtype : str
        Band 1 data type.
    """

    path: Path
    crs_wkt: str
    transform: Affine
    shape: tuple[int, int]
    count: int
    band_unit_m: float | None
    dtype: str

    @property
    def crs_name(self) -> str:
        """Human-readable CRS name."""
        return as_crs(self.crs_wkt).name

    def z_unit_m(self, override: float | None = None) -> float:
        """Metres per height unit: ``override``, else the band's tag, else the CRS's."""
        if override is not None:
            return float(override)
        if self.band_unit_m is not None:
            return self.band_unit_m
        return z_unit_m_of(self.crs_wkt)


def read_raster_info(path: str | Path) -> RasterInfo:
    """Open a raster's header.

    Raises
    ------
    InputFileError
        If the file is missing or not a raster GDAL can read.
    CrsError
        If it carries no CRS (it could not be placed in the site frame).
    DemError
        If its affine is singular.
    """
    import rasterio
    from rasterio.errors import RasterioIOError

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"raster not found: {path}")
    try:
        with rasterio.open(path) as ds:
            crs = ds.crs
            info = RasterInfo(
                path,
                "" if crs is None else crs.to_wkt(),
                ds.transform,
                (ds.height, ds.width),
                ds.count,
                unit_m_from_tag(ds.units[0]) if ds.count else None,
                ds.dtypes[0] if ds.count else "",
            )
    except RasterioIOError as exc:
        raise InputFileError(f"cannot read raster {path}: {str(exc).splitlines()[0]}") from None
    if not info.crs_wkt:
        raise CrsError(
            f"raster {path} has no CRS; tag it (e.g. gdal_edit.py -a_srs EPSG:XXXX) first"
        )
    as_crs(info.crs_wkt)  # an unknown CRS fails here with one line
    if abs(info.transform.determinant) == 0.0:
        raise DemError(f"raster {path} has a singular geotransform")
    return info


def raster_outline_lonlat(info: RasterInfo, n: int = 33) -> tuple[np.ndarray, np.ndarray]:
    """WGS84 ``(lon_deg, lat_deg)`` along the outline of the hull of cell centres.

    ``4 * n`` points; the hull of cell centres is where the raster's bilinear surface is
    defined.
    """
    rows, cols = info.shape
    t = np.linspace(0.0, 1.0, n)
    c_lo, c_hi, r_lo, r_hi = 0.5, cols - 0.5, 0.5, rows - 0.5
    cs = c_lo + (c_hi - c_lo) * t
    rs = r_lo + (r_hi - r_lo) * t
    col = np.concatenate([cs, np.full(n, c_hi), cs[::-1], np.full(n, c_lo)])
    row = np.concatenate([np.full(n, r_lo), rs, np.full(n, r_hi), rs[::-1]])
    # affine's stubs type only float vectors; at run time it broadcasts over arrays.
    x, y = info.transform @ (col, row)  # type: ignore[operator]
    hcrs = horizontal_crs(info.crs_wkt)
    lon, lat = cached_transformer(hcrs.to_wkt(), "EPSG:4326").transform(x, y)
    return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)


def footprint_bounds_local(
    infos: Sequence[RasterInfo], frame: LocalFrame
) -> tuple[float, float, float, float]:
    """Bounding box ``(e_min, n_min, e_max, n_max)`` (m, site frame) of the tiles' hulls.

    Taken at the anchor's height (local up 0); a terrain height ``dz`` moves the
    outline by ``dz * d / R``, millimetres over a site.
    """
    es, ns = [], []
    for info in infos:
        lon, lat = raster_outline_lonlat(info)
        e, n, _ = frame.to_enu(lat, lon, np.full_like(lat, frame.h_m))
        es.append(e)
        ns.append(n)
    e_all, n_all = np.concatenate(es), np.concatenate(ns)
    return float(e_all.min()), float(n_all.min()), float(e_all.max()), float(n_all.max())


def native_cell_m(info: RasterInfo, frame: LocalFrame) -> float:
    """Ground size (m) of the raster's smaller pixel side near the site anchor."""
    hcrs = horizontal_crs(info.crs_wkt)
    a, e = abs(info.transform.a), abs(info.transform.e)
    if hcrs.is_geographic:
        # Metres per degree of latitude / longitude on WGS84 at the anchor.
        lat = np.radians(frame.lat_deg)
        e2 = 0.00669437999014
        w = np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        m_lat = np.pi / 180.0 * 6378137.0 * (1.0 - e2) / w**3
        m_lon = np.pi / 180.0 * 6378137.0 * np.cos(lat) / w
        return float(min(a * m_lon, e * m_lat))
    unit = float(hcrs.axis_info[0].unit_conversion_factor)
    return float(min(a, e) * unit)


def grid_over(bounds: tuple[float, float, float, float], cell_m: float) -> GridSpec:
    """Grid of ``cell_m`` cells whose edges are multiples of ``cell_m`` covering ``bounds``."""
    if not (np.isfinite(cell_m) and cell_m > 0):
        raise DemError(f"cell size must be a positive number of metres, got {cell_m}")
    x0, y0, x1, y1 = bounds
    x_min = np.floor(x0 / cell_m) * cell_m
    y_min = np.floor(y0 / cell_m) * cell_m
    x_max = np.ceil(x1 / cell_m) * cell_m
    y_max = np.ceil(y1 / cell_m) * cell_m
    return GridSpec.covering(float(x_min), float(y_min), float(x_max), float(y_max), cell_m)


def _sample_height_at(info: RasterInfo, lon: float, lat: float) -> float:
    """Raw band-1 value of the cell containing ``(lon, lat)``, NaN outside or nodata."""
    import rasterio

    hcrs = horizontal_crs(info.crs_wkt)
    x, y = cached_transformer("EPSG:4326", hcrs.to_wkt()).transform(lon, lat)
    col, row = ~info.transform @ (x, y)
    r, c = int(np.floor(row)), int(np.floor(col))
    if not (0 <= r < info.shape[0] and 0 <= c < info.shape[1]):
        return float("nan")
    from rasterio.windows import Window

    with rasterio.open(info.path) as ds:
        v = ds.read(1, window=Window(c, r, 1, 1), masked=True).astype(np.float64)
    return float(v.filled(np.nan)[0, 0])


def suggest_frame(
    infos: Sequence[RasterInfo],
    *,
    geoid_undulation_m: float | GeoidModel = 0.0,
    z_unit_m: float | None = None,
) -> LocalFrame:
    """An anchor for a new site: the middle of the tiles' footprint, on the terrain.

    Latitude and longitude are the centre of the footprint's lon/lat bounding box; the
    height is the first tile's value there (ellipsoidal: ``H * z_unit + N``), or the
    anchor is at h = 0 when no tile has data there. Rounded to 1e-7 deg and 1 mm.
    """
    lons, lats = zip(*(raster_outline_lonlat(i) for i in infos), strict=True)
    lon_all, lat_all = np.concatenate(lons), np.concatenate(lats)
    lon0 = 0.5 * (lon_all.min() + lon_all.max())
    lat0 = 0.5 * (lat_all.min() + lat_all.max())
    h0 = 0.0
    for info in infos:
        v = _sample_height_at(info, lon0, lat0)
        if np.isfinite(v):
            n0 = float(as_geoid(geoid_undulation_m).undulation_m(lat0, lon0))
            h0 = v * info.z_unit_m(z_unit_m) + n0
            break
    return LocalFrame(round(float(lat0), 7), round(float(lon0), 7), round(float(h0), 3))


# --------------------------------------------------------------------------- mosaics


def _lattice_key(info: RasterInfo) -> tuple[Any, ...]:
    t = info.transform
    return (as_crs(info.crs_wkt).to_wkt(), t.a, t.b, t.d, t.e)


def _same_lattice(a: RasterInfo, b: RasterInfo) -> bool:
    if _lattice_key(a) != _lattice_key(b):
        return False
    col, row = ~a.transform @ (b.transform.c, b.transform.f)
    return abs(col - round(col)) < _LATTICE_TOL_PX and abs(row - round(row)) < _LATTICE_TOL_PX


def _group_tiles(infos: Sequence[RasterInfo]) -> list[list[int]]:
    groups: list[list[int]] = []
    for k, info in enumerate(infos):
        for g in groups:
            if _same_lattice(infos[g[0]], info):
                g.append(k)
                break
        else:
            groups.append([k])
    return groups


def _read_group(
    infos: Sequence[RasterInfo], frame: LocalFrame, grid: GridSpec
) -> tuple[np.ndarray, Affine, np.ndarray] | None:
    """Merge same-lattice tiles over the window the grid needs.

    Returns
    -------
    (values, transform, owner) or None
        ``values`` float64 (rows, cols) with NaN nodata, its affine, and ``owner``
        (int16, same shape) giving the index within ``infos`` of the tile that supplied
        each value (-1 for none). None when the grid does not reach any tile.
    """
    import rasterio
    from rasterio.windows import Window

    ref = infos[0].transform
    offsets = []
    for info in infos:
        col, row = ~ref @ (info.transform.c, info.transform.f)
        offsets.append((int(round(col)), int(round(row))))
    c_lo = min(o[0] for o in offsets)
    r_lo = min(o[1] for o in offsets)
    c_hi = max(o[0] + i.shape[1] for o, i in zip(offsets, infos, strict=True))
    r_hi = max(o[1] + i.shape[0] for o, i in zip(offsets, infos, strict=True))
    union_t = ref @ Affine.translation(c_lo, r_lo)
    shape = (r_hi - r_lo, c_hi - c_lo)
    w0, h0, w1, h1 = source_window(union_t, shape, infos[0].crs_wkt, frame, grid)
    w0, h0, w1, h1 = max(w0, 0), max(h0, 0), min(w1, shape[1]), min(h1, shape[0])
    if w1 <= w0 or h1 <= h0:
        return None
    values = np.full((h1 - h0, w1 - w0), np.nan)
    owner = np.full(values.shape, -1, dtype=np.int16)
    for k, (info, (oc, orow)) in enumerate(zip(infos, offsets, strict=True)):
        # Tile pixel window intersecting the needed union window.
        tc0, tr0 = oc - c_lo, orow - r_lo
        a0, b0 = max(w0, tc0), max(h0, tr0)
        a1, b1 = min(w1, tc0 + info.shape[1]), min(h1, tr0 + info.shape[0])
        if a1 <= a0 or b1 <= b0:
            continue
        with rasterio.open(info.path) as ds:
            block = ds.read(1, window=Window(a0 - tc0, b0 - tr0, a1 - a0, b1 - b0), masked=True)
        data = np.ma.filled(block.astype(np.float64), np.nan)
        data[~np.isfinite(data)] = np.nan
        dst = (slice(b0 - h0, b1 - h0), slice(a0 - w0, a1 - w0))
        take = np.isnan(values[dst]) & np.isfinite(data)  # tiles listed first win
        values[dst][take] = data[take]
        owner[dst][take] = k
    return values, union_t @ Affine.translation(w0, h0), owner


@dataclass(frozen=True, eq=False)
class DemImport:
    """Result of :func:`import_dem`.

    Attributes
    ----------
    dem : Dem
        The site DEM: count 1 where a tile supplied the cell, filled cells flagged.
    tile_cells : tuple of int
        Cells each input tile supplied (in the order given).
    filled_cells : int
        Cells filled from the coarse DEM.
    hole_cells : int
        Cells left without data.
    groups : tuple of tuple of int
        Tiles merged into one source raster (same CRS and pixel lattice).
    source : ndarray, int32, shape (nrows, ncols), or None
        Index of the tile that supplied each cell (-1: none).
    """

    dem: Dem
    tile_cells: tuple[int, ...]
    filled_cells: int
    hole_cells: int
    groups: tuple[tuple[int, ...], ...]
    source: np.ndarray | None = None


def import_dem(
    paths: Sequence[str | Path],
    frame: LocalFrame,
    grid: GridSpec,
    *,
    coarse: str | Path | None = None,
    geoid_undulation_m: float | GeoidModel = 0.0,
    z_unit_m: float | None = None,
    sigma_m: float = 0.0,
    coarse_sigma_m: float = 1.0,
    crs_wkt: str | None = None,
    resampling: str = "bilinear",
) -> DemImport:
    """Warp and mosaic DEM tiles (any CRS) onto ``grid``, then fill holes from ``coarse``.

    Parameters
    ----------
    paths : sequence of path
        GeoTIFF tiles, highest priority first (the first listed wins where they overlap).
    frame : LocalFrame
        The site frame.
    grid : GridSpec
        Target grid (m, site frame).
    coarse : path, optional
        A coarse DEM in any CRS, same vertical datum as the tiles, for the holes.
    geoid_undulation_m : float or GeoidModel
        The tiles' geoid when their heights are orthometric: a
        :class:`~demtrack.core.geo.geoid.GeoidModel` (``N`` evaluated at each cell's
        lat/lon, e.g. EGM96) or a constant ``N`` (m); 0 when they are ellipsoidal.
    z_unit_m : float, optional
        Metres per height unit for every input; default per file (band unit tag, else
        the CRS's vertical or horizontal unit, so a ftUS state plane means ftUS heights).
    sigma_m, coarse_sigma_m : float
        1-sigma vertical error of the tiles and of the coarse DEM (m), stored as the
        cells' variance so that geolocation uncertainty includes it.
    crs_wkt : str, optional
        CRS stored with the DEM (normally :func:`~demtrack.core.terrain.crs_import.local_crs_wkt`).
    resampling : {"bilinear", "cubic", "nearest", "average"}
        How the tiles are sampled at the site's cells
        (:func:`~demtrack.core.terrain.crs_import.warp_to_local`); the coarse DEM is always
        bilinear.

    Returns
    -------
    DemImport

    Raises
    ------
    InputFileError, CrsError, DemError
        On an unreadable tile, a tile without a CRS, or when no tile (nor the coarse
        DEM) reaches the grid.
    """
    if not paths:
        raise DemError("no DEM tiles given")
    infos = [read_raster_info(p) for p in paths]
    for info in infos:
        if info.count < 1:
            raise DemError(f"raster {info.path} has no band")
    coarse_info = read_raster_info(coarse) if coarse is not None else None
    elev = np.full(grid.shape, np.nan, dtype=np.float32)
    source = np.full(grid.shape, -1, dtype=np.int32)
    groups = _group_tiles(infos)
    for group in groups:
        members = [infos[k] for k in group]
        merged = _read_group(members, frame, grid)
        if merged is None:
            continue
        values, transform, owner = merged
        k_m = members[0].z_unit_m(z_unit_m)
        z = warp_to_local(
            values,
            transform,
            members[0].crs_wkt,
            frame,
            grid,
            geoid_undulation_m=geoid_undulation_m,
            z_unit_m=k_m,
            resampling=resampling,
        )
        # Which tile supplied a cell: the owner of the source cell nearest its centre.
        who = warp_to_local(
            np.where(owner >= 0, owner, np.nan).astype(np.float64),
            transform,
            members[0].crs_wkt,
            frame,
            grid,
            kind="image",
        )
        take = np.isnan(elev) & np.isfinite(z)
        elev[take] = z[take]
        who_idx = np.where(np.isfinite(who), np.rint(np.nan_to_num(who)), 0).astype(np.int64)
        source[take] = np.asarray(group)[np.clip(who_idx[take], 0, len(group) - 1)]
    from_tiles = np.isfinite(elev)
    filled = np.zeros(grid.shape, dtype=bool)
    if coarse_info is not None and not from_tiles.all():
        c = warp_to_local(
            *_read_whole_window(coarse_info, frame, grid),
            coarse_info.crs_wkt,
            frame,
            grid,
            geoid_undulation_m=geoid_undulation_m,
            z_unit_m=coarse_info.z_unit_m(z_unit_m),
        )
        filled = ~from_tiles & np.isfinite(c)
        elev[filled] = c[filled]
    if not np.isfinite(elev).any():
        names = ", ".join(str(p) for p in paths)
        raise DemError(f"the DEM tiles ({names}) do not reach the site grid {grid.bounds}")
    var = np.where(filled, coarse_sigma_m**2, sigma_m**2).astype(np.float32)
    dem = Dem(grid, elev, var, from_tiles.astype(np.int32), filled, crs_wkt)
    tile_cells = tuple(int(np.count_nonzero(source == k)) for k in range(len(infos)))
    return DemImport(
        dem,
        tile_cells,
        int(filled.sum()),
        int(np.isnan(elev).sum()),
        tuple(tuple(g) for g in groups),
        source,
    )


def _largest_rectangle_exact(inside: np.ndarray) -> tuple[int, int, int, int]:
    """Histogram-and-stack maximal rectangle of True cells, O(nrows * ncols) steps."""
    nrows, ncols = inside.shape
    heights = np.zeros(ncols + 1, dtype=np.int64)  # a 0 sentinel closes every run
    best = (0, 0, 0, 0, 0)
    for r in range(nrows):
        heights[:ncols] = np.where(inside[r], heights[:ncols] + 1, 0)
        stack: list[int] = []
        for c in range(ncols + 1):
            while stack and heights[stack[-1]] >= heights[c]:
                h = int(heights[stack.pop()])
                left = stack[-1] + 1 if stack else 0
                area = h * (c - left)
                if area > best[0]:
                    best = (area, r - h + 1, r + 1, left, c)
            stack.append(c)
    return best[1], best[2], best[3], best[4]


def largest_data_rectangle(
    valid: np.ndarray, exact_side: int = _RECT_EXACT_SIDE
) -> tuple[int, int, int, int]:
    """The largest axis-aligned rectangle of cells inside the data's footprint.

    Parameters
    ----------
    valid : ndarray, bool, shape (nrows, ncols)
        Cells with data. Gaps enclosed by data (a lake, a void) count as inside: they do
        not shrink the rectangle, only the footprint's outline does.
    exact_side : int
        Grids up to this many cells a side are searched exactly (the classic
        histogram-and-stack method). Larger ones are searched on blocks of cells (a
        block counts only when all its cells are inside), then each side of the found
        rectangle is pushed out cell by cell while the new row or column is all inside:
        within a block's width of the largest rectangle, and always inside.

    Returns
    -------
    (r0, r1, c0, c1) : int
        Rows ``r0:r1`` and columns ``c0:c1`` (exclusive ends).

    Raises
    ------
    DemError
        If no cell has data.
    """
    from scipy.ndimage import binary_fill_holes

    inside = np.asarray(binary_fill_holes(np.asarray(valid, dtype=bool)), dtype=bool)
    if not inside.any():
        raise DemError("no cell has data")
    nrows, ncols = inside.shape
    f = int(np.ceil(max(nrows, ncols) / exact_side))
    if f <= 1:
        return _largest_rectangle_exact(inside)
    pr, pc = -nrows % f, -ncols % f
    padded = np.pad(inside, ((0, pr), (0, pc)), constant_values=False)
    blocks = np.asarray(
        padded.reshape(padded.shape[0] // f, f, padded.shape[1] // f, f).all(axis=(1, 3))
    )
    if not blocks.any():
        return _largest_rectangle_exact(inside)
    b0, b1, d0, d1 = _largest_rectangle_exact(blocks)
    r0, r1, c0, c1 = b0 * f, min(b1 * f, nrows), d0 * f, min(d1 * f, ncols)
    grown = True
    while grown:
        grown = False
        if r0 > 0 and inside[r0 - 1, c0:c1].all():
            r0, grown = r0 - 1, True
        if r1 < nrows and inside[r1, c0:c1].all():
            r1, grown = r1 + 1, True
        if c0 > 0 and inside[r0:r1, c0 - 1].all():
            c0, grown = c0 - 1, True
        if c1 < ncols and inside[r0:r1, c1].all():
            c1, grown = c1 + 1, True
    return r0, r1, c0, c1


def sub_grid(grid: GridSpec, r0: int, r1: int, c0: int, c1: int) -> GridSpec:
    """Rows ``r0:r1`` and columns ``c0:c1`` of ``grid`` as a grid of their own."""
    return GridSpec(
        grid.x_min + c0 * grid.cell_m, grid.y_max - r0 * grid.cell_m, grid.cell_m, r1 - r0, c1 - c0
    )


def crop_import(result: DemImport, r0: int, r1: int, c0: int, c1: int) -> DemImport:
    """The import cut to rows ``r0:r1``, columns ``c0:c1`` (the same cells, not re-warped).

    Tile counts are recounted from the cropped cells' sources.
    """
    sl = (slice(r0, r1), slice(c0, c1))
    d = result.dem
    dem = Dem(
        sub_grid(d.grid, r0, r1, c0, c1),
        d.elevation[sl],
        d.variance[sl],
        d.count[sl],
        d.filled[sl],
        d.crs_wkt,
        d.vertical_datum,
    )
    full = result.source
    if full is None:
        full = np.where(result.dem.count > 0, 0, -1).astype(np.int32)
    src = full[sl]
    return DemImport(
        dem,
        tuple(int(np.count_nonzero(src == k)) for k in range(len(result.tile_cells))),
        int(dem.filled.sum()),
        int(dem.nodata.sum()),
        result.groups,
        src,
    )


def _read_whole_window(
    info: RasterInfo, frame: LocalFrame, grid: GridSpec
) -> tuple[np.ndarray, Affine]:
    merged = _read_group([info], frame, grid)
    if merged is None:
        return np.full((1, 1), np.nan), info.transform
    return merged[0], merged[1]
