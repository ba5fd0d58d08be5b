"""Georeferencing of regular north-up grids.

Convention (see ``docs/conventions.md``): a cell's value belongs to its centre. Row 0 is
the northern-most row, column 0 the western-most. Cell ``(r, c)`` has its centre at::

    x = x_min + (c + 0.5) * cell_m
    y = y_max - (r + 0.5) * cell_m

"Grid coordinates" ``(gx, gy)`` are fractional column/row indices of cell centres:
``gx = (x - x_min) / cell_m - 0.5`` and ``gy = (y_max - y) / cell_m - 0.5``, so the centre
of cell ``(r, c)`` is at ``(gx, gy) = (c, r)``. The continuous surfaces built on a grid
(bilinear interpolation of centre values) are defined on the hull of cell centres,
``0 <= gx <= ncols - 1`` and ``0 <= gy <= nrows - 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from affine import Affine

from ..errors import DemError

__all__ = ["GridSpec"]


@dataclass(frozen=True)
class GridSpec:
    """A regular north-up grid of square cells.

    Parameters
    ----------
    x_min, y_max : float
        Coordinates (m, in the grid's frame) of the north-west corner of the grid, i.e.
        the outer corner of cell (0, 0), not its centre.
    cell_m : float
        Cell edge length in metres (> 0).
    nrows, ncols : int
        Grid shape (>= 1 each).
    """

    x_min: float
    y_max: float
    cell_m: float
    nrows: int
    ncols: int

    def __post_init__(self) -> None:
        if not (np.isfinite(self.cell_m) and self.cell_m > 0):
            raise DemError(f"cell size must be a positive number of metres, got {self.cell_m}")
        if not (np.isfinite(self.x_min) and np.isfinite(self.y_max)):
            raise DemError("grid origin must be finite")
        if int(self.nrows) < 1 or int(self.ncols) < 1:
            raise DemError(f"grid shape must be at least 1 x 1, got {self.nrows} x {self.ncols}")
        object.__setattr__(self, "nrows", int(self.nrows))
        object.__setattr__(self, "ncols", int(self.ncols))

    @property
    def shape(self) -> tuple[int, int]:
        """``(nrows, ncols)``."""
        return (self.nrows, self.ncols)

    @property
    def x_max(self) -> float:
        """East edge of the grid (m)."""
        return self.x_min + self.ncols * self.cell_m

    @property
    def y_min(self) -> float:
        """South edge of the grid (m)."""
        return self.y_max - self.nrows * self.cell_m

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Outer edges ``(x_min, y_min, x_max, y_max)`` in metres."""
        return (self.x_min, self.y_min, self.x_max, self.y_max)

    @property
    def centre_bounds(self) -> tuple[float, float, float, float]:
        """Hull of cell centres ``(x_min, y_min, x_max, y_max)``: the surface's domain."""
        h = 0.5 * self.cell_m
        return (self.x_min + h, self.y_min + h, self.x_max - h, self.y_max - h)

    @property
    def transform(self) -> Affine:
        """Rasterio/GDAL affine transform (maps pixel corners, as GeoTIFF does)."""
        return Affine(self.cell_m, 0.0, self.x_min, 0.0, -self.cell_m, self.y_max)

    @classmethod
    def from_transform(cls, transform: Affine, nrows: int, ncols: int) -> GridSpec:
        """Build from a north-up rasterio transform with square cells."""
        if abs(transform.b) > 1e-12 or abs(transform.d) > 1e-12:
            raise DemError("raster is rotated or sheared; only north-up grids are supported")
        if transform.e >= 0:
            raise DemError("raster is not north-up (positive y pixel size)")
        if not np.isclose(transform.a, -transform.e, rtol=1e-9, atol=0.0):
            raise DemError(f"cells are not square ({transform.a} x {-transform.e})")
        return cls(float(transform.c), float(transform.f), float(transform.a), nrows, ncols)

    @classmethod
    def covering(
        cls, x_min: float, y_min: float, x_max: float, y_max: float, cell_m: float
    ) -> GridSpec:
        """Smallest grid with origin ``(x_min, y_max)`` whose cells cover the box."""
        if not (x_max > x_min and y_max > y_min):
            raise DemError(f"empty bounds ({x_min}, {y_min}, {x_max}, {y_max})")
        ncols = max(1, int(np.ceil((x_max - x_min) / cell_m - 1e-9)))
        nrows = max(1, int(np.ceil((y_max - y_min) / cell_m - 1e-9)))
        return cls(float(x_min), float(y_max), float(cell_m), nrows, ncols)

    def to_grid(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates (m) to fractional grid coordinates ``(gx, gy)``."""
        gx = (np.asarray(x, dtype=np.float64) - self.x_min) / self.cell_m - 0.5
        gy = (self.y_max - np.asarray(y, dtype=np.float64)) / self.cell_m - 0.5
        return gx, gy

    def from_grid(self, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map fractional grid coordinates back to coordinates (m)."""
        x = self.x_min + (np.asarray(gx, dtype=np.float64) + 0.5) * self.cell_m
        y = self.y_max - (np.asarray(gy, dtype=np.float64) + 0.5) * self.cell_m
        return x, y

    def cell_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column of the cell containing each point; -1 where outside."""
        col = np.floor((np.asarray(x, dtype=np.float64) - self.x_min) / self.cell_m)
        row = np.floor((self.y_max - np.asarray(y, dtype=np.float64)) / self.cell_m)
        inside = (col >= 0) & (col < self.ncols) & (row >= 0) & (row < self.nrows)
        return (
            np.where(inside, row, -1).astype(np.int64),
            np.where(inside, col, -1).astype(np.int64),
        )

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates as two ``(nrows, ncols)`` arrays ``(x, y)``."""
        gx, gy = np.meshgrid(
            np.arange(self.ncols, dtype=np.float64), np.arange(self.nrows, dtype=np.float64)
        )
        return self.from_grid(gx, gy)
