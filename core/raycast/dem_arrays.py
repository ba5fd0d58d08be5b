"""The DEM and its min/max pyramid as the casting kernels take them, packed once.

Every DEM ray-casting kernel (``core.raycast._kernels``, the light and angular twins, the
viewshed's sight lines) starts with the same ten arguments: the elevation grid, the
pyramid's nodes, level offsets and shapes, the grid's georeferencing, the terrain's height
range and the height slack. :class:`DemArrays` holds them in that order, so a call is
``kernel(*dem_arrays, <the kernel's own arguments>)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..terrain.grid import GridSpec
from .pyramid import MinMaxPyramid

__all__ = ["DemArrays"]


class DemArrays(NamedTuple):
    """The first ten arguments of every DEM ray-casting kernel.

    Attributes
    ----------
    elev : ndarray, float32, shape (nrows, ncols)
        Cell-centre elevations (m, local-frame Z), NaN = nodata; read-only, C-contiguous.
    nodes, lvl_off, lvl_shape : ndarray
        The min/max pyramid (``core.raycast.pyramid.MinMaxPyramid``).
    x_min, y_max, cell : float
        Grid georeferencing (m, local frame).
    z_min, z_max : float
        Terrain height range (m).
    margin : float
        Slack (m) around the height range and in every min/max test.
    """

    elev: np.ndarray
    nodes: np.ndarray
    lvl_off: np.ndarray
    lvl_shape: np.ndarray
    x_min: float
    y_max: float
    cell: float
    z_min: float
    z_max: float
    margin: float

    @classmethod
    def pack(
        cls, grid: GridSpec, elevation: np.ndarray, pyramid: MinMaxPyramid, margin: float
    ) -> DemArrays:
        """Pack a grid, its elevations, their pyramid and the height slack (m)."""
        p = pyramid
        return cls(
            elevation,
            p.nodes,
            p.level_offsets,
            p.level_shapes,
            float(grid.x_min),
            float(grid.y_max),
            float(grid.cell_m),
            p.z_min,
            p.z_max,
            margin,
        )
