"""Digital elevation models on a regular grid in the site's local frame.

A :class:`Dem` holds, per cell, the mean elevation, its variance and the number of laser
points behind it, exactly as the VSAM report builds its 0.5 m site DEM (Collins et al.
1998, section 2): every point falls in one cell by its x, y; empty cells are holes, later
filled by bilinear interpolation of a coarse (30 m) DEM.

Heights are local-frame Z (metres, up along the ellipsoid normal at the site anchor; see
``docs/conventions.md``). Nodata is NaN in ``elevation``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import DemError, InputFileError
from .grid import GridSpec
from .surface import bilinear_sample

if TYPE_CHECKING:
    from ..raycast.cast import RayCaster

__all__ = ["Dem", "VERTICAL_DATUM_LOCAL"]

#: The vertical datum of every elevation stored by a site DEM.
VERTICAL_DATUM_LOCAL = "local-frame Z: up along the WGS84 ellipsoid normal at the site anchor"

# Default of the optional per-cell arrays: omitted at construction, ``__post_init__``
# replaces it with zeros, so on a built Dem the attribute is always an ndarray.
_FILLED_BY_POST_INIT = cast("np.ndarray", None)


@dataclass(frozen=True, eq=False)
class Dem:
    """A gridded elevation model with per-cell statistics.

    Parameters
    ----------
    grid : GridSpec
        Georeferencing in the site frame (metres).
    elevation : ndarray, float32, shape (nrows, ncols)
        Mean elevation of each cell (m); NaN where there is no data.
    variance : ndarray, float32, shape (nrows, ncols)
        Variance of the elevations that fell in the cell (m^2, population variance);
        for cells filled from a coarser model, the variance assumed for that model.
        NaN where ``elevation`` is NaN.
    count : ndarray, int32, shape (nrows, ncols)
        Number of source points in the cell (0 for empty or filled cells).
    filled : ndarray, bool, shape (nrows, ncols)
        True where the elevation came from hole filling rather than points.
    crs_wkt : str or None
        WKT of the 2-D CRS whose x, y are the grid's coordinates, if known.
    vertical_datum : str
        Plain statement of what the elevations are measured from.
    """

    grid: GridSpec
    elevation: np.ndarray
    variance: np.ndarray = field(default=_FILLED_BY_POST_INIT)
    count: np.ndarray = field(default=_FILLED_BY_POST_INIT)
    filled: np.ndarray = field(default=_FILLED_BY_POST_INIT)
    crs_wkt: str | None = None
    vertical_datum: str = VERTICAL_DATUM_LOCAL

    def __post_init__(self) -> None:
        shape = self.grid.shape
        elev = np.ascontiguousarray(self.elevation, dtype=np.float32)
        if elev.shape != shape:
            raise DemError(f"elevation has shape {elev.shape}, grid says {shape}")
        if np.isinf(elev).any():
            raise DemError("elevation contains infinite values")
        var = (
            np.zeros(shape, np.float32)
            if self.variance is None
            else np.ascontiguousarray(self.variance, dtype=np.float32)
        )
        cnt = (
            np.zeros(shape, np.int32)
            if self.count is None
            else np.ascontiguousarray(self.count, dtype=np.int32)
        )
        fil = (
            np.zeros(shape, bool)
            if self.filled is None
            else np.ascontiguousarray(self.filled, dtype=bool)
        )
        for name, arr in (("variance", var), ("count", cnt), ("filled", fil)):
            if arr.shape != shape:
                raise DemError(f"{name} has shape {arr.shape}, grid says {shape}")
        var = np.where(np.isnan(elev), np.float32(np.nan), var).astype(np.float32)
        for name, arr in (("elevation", elev), ("variance", var), ("count", cnt), ("filled", fil)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    # ------------------------------------------------------------------ properties
    @property
    def nodata(self) -> np.ndarray:
        """Boolean mask of cells without an elevation, shape (nrows, ncols)."""
        return np.isnan(self.elevation)

    @property
    def coverage(self) -> float:
        """Share of cells with an elevation from points (not filled, not empty)."""
        return float(np.count_nonzero(self.count > 0)) / self.elevation.size

    def elevation_range(self) -> tuple[float, float]:
        """Minimum and maximum elevation (m) over cells with data."""
        if self.nodata.all():
            raise DemError("DEM has no data")
        return float(np.nanmin(self.elevation)), float(np.nanmax(self.elevation))

    # ------------------------------------------------------------------ building
    @classmethod
    def from_points(
        cls,
        xyz: np.ndarray,
        cell_size: float = 0.5,
        bounds: tuple[float, float, float, float] | None = None,
        crs_wkt: str | None = None,
    ) -> Dem:
        """Grid a point cloud: per cell mean elevation, variance and count.

        Parameters
        ----------
        xyz : ndarray, shape (n, 3)
            Points in the site frame (m). Non-finite rows are ignored.
        cell_size : float
            Cell edge (m); the paper uses 0.5 m.
        bounds : (x_min, y_min, x_max, y_max), optional
            Outer edges of the grid. By default the points' bounding box, with the origin
            snapped down to a multiple of ``cell_size``. Points outside are ignored.
        crs_wkt : str, optional
            CRS of the x, y coordinates, stored with the DEM.

        Returns
        -------
        Dem
            Cells without points are NaN (holes) with count 0.

        Notes
        -----
        Each point falls in exactly one cell by ``floor`` of its grid position (a point on
        a shared edge goes to the cell east / south of it). Variance is the population
        variance, computed in two passes (mean, then squared deviations) for accuracy.
        """
        pts = np.asarray(xyz, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise DemError(f"points must have shape (n, 3), got {pts.shape}")
        pts = pts[np.isfinite(pts).all(axis=1)]
        if bounds is None:
            if len(pts) == 0:
                raise DemError("no finite points to build a DEM from")
            x0 = np.floor(pts[:, 0].min() / cell_size) * cell_size
            y0 = np.floor(pts[:, 1].min() / cell_size) * cell_size
            # +1 cell so a point on the max edge still falls inside.
            ncols = int(np.floor((pts[:, 0].max() - x0) / cell_size)) + 1
            nrows = int(np.floor((pts[:, 1].max() - y0) / cell_size)) + 1
            grid = GridSpec(
                float(x0), float(y0 + nrows * cell_size), float(cell_size), nrows, ncols
            )
        else:
            bx0, by0, bx1, by1 = (float(b) for b in bounds)
            grid = GridSpec.covering(bx0, by0, bx1, by1, float(cell_size))
        rows, cols = grid.cell_of(pts[:, 0], pts[:, 1])
        keep = rows >= 0
        flat = rows[keep] * grid.ncols + cols[keep]
        z = pts[keep, 2]
        n = grid.nrows * grid.ncols
        count = np.bincount(flat, minlength=n)
        total = np.bincount(flat, weights=z, minlength=n)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = total / count
        dev = z - mean[flat]
        sq_dev = np.bincount(flat, weights=dev * dev, minlength=n)
        with np.errstate(invalid="ignore", divide="ignore"):
            variance = sq_dev / count
        shape = grid.shape
        return cls(
            grid,
            mean.reshape(shape),
            variance.reshape(shape),
            count.reshape(shape).astype(np.int32),
            crs_wkt=crs_wkt,
        )

    def fill_holes(self, coarse: Dem, coarse_sigma_m: float = 1.0) -> Dem:
        """Fill empty cells by bilinear interpolation of a coarser DEM.

        Parameters
        ----------
        coarse : Dem
            A coarse model in the same frame (the paper uses a 30 m USGS DEM); sampled
            bilinearly at each hole's cell centre.
        coarse_sigma_m : float
            1-sigma vertical error assumed for the coarse model; stored as the variance of
            filled cells so that geolocation uncertainty reflects it.

        Returns
        -------
        Dem
            A new DEM; ``filled`` marks the cells that were filled. Holes outside the
            coarse model's coverage stay NaN.
        """
        holes = self.nodata
        if not holes.any():
            return self
        x, y = self.grid.centres()
        z = coarse.sample(x[holes], y[holes])
        elev = np.array(self.elevation)
        var = np.array(self.variance)
        elev[holes] = z
        var[holes] = np.float32(coarse_sigma_m**2)
        filled = np.array(self.filled)
        filled[holes] = np.isfinite(z)
        return replace(self, elevation=elev, variance=var, filled=filled)

    # ------------------------------------------------------------------ queries
    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear elevation over cell centres at site coordinates (m).

        The same function as the terrain surface the ray caster intersects. NaN outside
        the hull of cell centres or where any of the four surrounding centres is NaN.
        """
        gx, gy = self.grid.to_grid(x, y)
        return bilinear_sample(self.elevation, gx, gy)

    def sample_variance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of the per-cell variance (m^2) at site coordinates."""
        gx, gy = self.grid.to_grid(x, y)
        return bilinear_sample(self.variance, gx, gy)

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slope ``(dz/dx, dz/dy)`` of the bilinear surface at site coordinates."""
        h = 1e-3 * self.grid.cell_m
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        # the four offset samples in one call (the same values as four calls)
        z = self.sample(np.stack([x + h, x - h, x, x]), np.stack([y, y, y + h, y - h]))
        dzdx = (z[0] - z[1]) / (2 * h)
        dzdy = (z[2] - z[3]) / (2 * h)
        return dzdx, dzdy

    def ray_caster(self) -> RayCaster:
        """Return the DEM prepared for ray casting; built on first use, then shared.

        The same caster as :meth:`RayCaster.for_dem(dem)
        <demtrack.core.raycast.cast.RayCaster.for_dem>`, which holds the cache (callers in
        the library use that; this method stays for code that has a ``Dem`` only).
        """
        from ..raycast.cast import RayCaster  # numba loads only when rays are cast

        return RayCaster.for_dem(self)

    # ------------------------------------------------------------------ GeoTIFF
    def write(self, path: str | Path) -> None:
        """Write a 3-band float32 GeoTIFF: elevation, variance, count (nodata NaN)."""
        import rasterio

        g = self.grid
        profile = {
            "driver": "GTiff",
            "height": g.nrows,
            "width": g.ncols,
            "count": 3,
            "dtype": "float32",
            "transform": g.transform,
            "nodata": float("nan"),
            "compress": "deflate",
            "tiled": True,
            "blockxsize": 256,
            "blockysize": 256,
        }
        if g.nrows < 256 or g.ncols < 256:
            profile.update(tiled=False)
            profile.pop("blockxsize")
            profile.pop("blockysize")
        if self.crs_wkt:
            profile["crs"] = self.crs_wkt
        count = self.count.astype(np.float32)
        count[self.filled] = np.nan  # distinguishes filled cells on disk
        with rasterio.open(Path(path), "w", **profile) as dst:
            dst.write(self.elevation, 1)
            dst.write(self.variance, 2)
            dst.write(count, 3)
            dst.set_band_description(1, "elevation_m")
            dst.set_band_description(2, "variance_m2")
            dst.set_band_description(3, "count")
            dst.update_tags(VERTICAL_DATUM=self.vertical_datum, CELL_VALUE_AT="centre")

    @classmethod
    def read(cls, path: str | Path) -> Dem:
        """Read a DEM GeoTIFF.

        Three-band files written by :meth:`write` restore variance, count and filled
        cells; any single-band elevation GeoTIFF is accepted too (variance 0, count 1).
        """
        import rasterio
        from rasterio.errors import RasterioError

        path = Path(path)
        try:
            with rasterio.open(path) as src:
                elev = src.read(1).astype(np.float32)
                if src.nodata is not None and not np.isnan(src.nodata):
                    elev[elev == np.float32(src.nodata)] = np.nan
                grid = GridSpec.from_transform(src.transform, src.height, src.width)
                crs_wkt = src.crs.to_wkt() if src.crs else None
                datum = src.tags().get("VERTICAL_DATUM", "unknown (not stated in file)")
                if src.count >= 3:
                    var = src.read(2).astype(np.float32)
                    cnt_f = src.read(3).astype(np.float32)
                    filled = np.isnan(cnt_f) & ~np.isnan(elev)
                    cnt = np.nan_to_num(cnt_f, nan=0.0).astype(np.int32)
                else:
                    var = np.zeros_like(elev)
                    cnt = np.where(np.isnan(elev), 0, 1).astype(np.int32)
                    filled = None
        except RasterioError as exc:
            raise InputFileError(f"cannot read DEM {path}: {_read_problem(exc)}") from None
        return cls(grid, elev, var, cnt, filled, crs_wkt, datum)


def _read_problem(exc: Exception) -> str:
    """What is wrong with a raster file rasterio could not read, in one line.

    rasterio says "Read failed. See previous exception for details." when the header
    opens but the pixel data does not (a truncated or damaged file); GDAL's own message is
    the exception's cause.
    """
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if "Read failed" not in text:
        return text
    cause = exc.__cause__ or exc.__context__
    detail = str(cause).strip().splitlines()[0] if cause is not None and str(cause).strip() else ""
    return "the file is truncated or corrupt: its pixel data cannot be read" + (
        f" ({detail})" if detail else ""
    )
