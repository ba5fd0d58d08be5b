"""Scene geometry: the terrain mesh and its texture coordinates, roads and polylines.

Pure numpy, in the site frame (x east, y north, z up, m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from demtrack.core.site.folder import Site
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

__all__ = ["TerrainMesh", "polyline_segments", "road_polylines", "terrain_mesh", "texture_uv"]

#: Lines (roads, tracks) and the followed head are drawn this far (m) above the terrain
#: so that the mesh does not swallow them.
_LIFT_M = 0.4


@dataclass(frozen=True)
class TerrainMesh:
    """A triangle mesh of the DEM surface.

    Attributes
    ----------
    vertices : ndarray, shape (n, 3)
        Site frame (m): decimated cell centres at their elevation.
    faces : ndarray, shape (m, 3)
        Vertex indices, counter-clockwise seen from above (normals up); no face
        touches a nodata cell.
    """

    vertices: np.ndarray
    faces: np.ndarray


def _take(n: int, step: int) -> np.ndarray:
    """Every ``step``-th index of ``range(n)``, always including the last."""
    idx = np.arange(0, n, step)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def terrain_mesh(dem: Dem, max_side: int = 250) -> TerrainMesh:
    """The DEM's surface on at most ``max_side`` vertices per side.

    Vertices are cell centres (every ``step``-th row and column, always including the
    last), at the cell's elevation.

    Parameters
    ----------
    dem : Dem
        The terrain (site frame, m).
    max_side : int
        Most vertices along a side.

    Returns
    -------
    TerrainMesh
    """
    g = dem.grid
    step = max(1, math.ceil(max(g.nrows, g.ncols) / max_side))
    rows, cols = _take(g.nrows, step), _take(g.ncols, step)
    z = np.asarray(dem.elevation, dtype=np.float64)[np.ix_(rows, cols)]
    x = g.x_min + (cols + 0.5) * g.cell_m
    y = g.y_max - (rows + 0.5) * g.cell_m
    xx, yy = np.meshgrid(x, y)
    ok = np.isfinite(z)
    zf = np.where(ok, z, np.nanmin(z) if ok.any() else 0.0)
    vertices = np.column_stack([xx.ravel(), yy.ravel(), zf.ravel()])
    nr, nc = len(rows), len(cols)
    idx = np.arange(nr * nc).reshape(nr, nc)
    nw, ne, sw, se = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    okf = ok.ravel()
    tris = np.concatenate(
        [np.stack([nw, sw, se], -1).reshape(-1, 3), np.stack([nw, se, ne], -1).reshape(-1, 3)]
    )
    tris = tris[okf[tris].all(axis=1)]
    return TerrainMesh(vertices, tris.astype(np.int32))


def texture_uv(xy: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Texture coordinates of site-frame points on an image covering ``grid``.

    ``u`` runs west to east over the grid's outer edges and ``v`` south to north
    (0 at the bottom row's southern edge), the OBJ / trimesh convention.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Site frame east, north (m).
    grid : GridSpec
        The image's grid (row 0 north).

    Returns
    -------
    ndarray, shape (n, 2)
    """
    xy = np.asarray(xy, dtype=np.float64)
    u = (xy[:, 0] - grid.x_min) / (grid.ncols * grid.cell_m)
    v = (xy[:, 1] - grid.y_min) / (grid.nrows * grid.cell_m)
    return np.column_stack([u, v])


def road_polylines(site: Site, step_m: float = 2.0, lift_m: float = _LIFT_M) -> list[np.ndarray]:
    """Road centre lines draped on the DEM.

    Parameters
    ----------
    site : Site
        Its roads (none: no lines) and DEM.
    step_m : float
        Most distance (m) between consecutive points along a line.
    lift_m : float
        Height (m) above the DEM.

    Returns
    -------
    list of ndarray, each shape (k, 3)
        Site frame (m); points off the DEM are dropped, and lines left with fewer than
        two points.
    """
    if site.roads is None:
        return []
    out = []
    for line in site.roads.lines:
        n = max(2, int(math.ceil(line.length / step_m)) + 1)
        pts = np.array([line.interpolate(s).coords[0] for s in np.linspace(0, line.length, n)])
        z = site.dem.sample(pts[:, 0], pts[:, 1])
        keep = np.isfinite(z)
        if keep.sum() >= 2:
            out.append(np.column_stack([pts[keep, :2], z[keep] + lift_m]))
    return out


def polyline_segments(points: np.ndarray) -> np.ndarray:
    """Consecutive point pairs of a polyline.

    Parameters
    ----------
    points : ndarray, shape (k, 3)

    Returns
    -------
    ndarray, shape (k - 1, 2, 3)
    """
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[:-1], p[1:]], axis=1)
