"""Sparse point clouds on a grid: a TIN between the points, fitted to the bilinear surface.

A 1 m grid over real lidar at 0.4 ground points per m^2 leaves about 70 % of the cells
without a point, and a ray cannot hit a hole. Here the gaps are interpolated from the
points themselves, as PDAL and lidR do, by a TIN (Delaunay triangulation of the points,
barycentric interpolation in each triangle; :mod:`scipy.spatial`):

1. The TIN of the points is evaluated at every cell centre inside the points' convex hull.
   Cell centres within one cell (Chebyshev distance) outside the hull take the value of
   the nearest point, so the bilinear surface over cell centres covers the whole hull: a
   point inside the hull always has its four surrounding centres. Every other cell stays
   a hole.
2. ``method="fit"`` (ground models): the cell-centre elevations are the least-squares fit
   of the bilinear surface to the points, with the TIN of step 1 as a prior of weight
   ``prior_weight`` per cell (in units of one point's weight). Where a cell holds many
   points the fit is their local mean (the paper's cell value); between points it
   follows the TIN. Measured on the Autzen tile (0.42 ground points per m^2, 1 m cells,
   10 % held out): held-out RMSE 5.40 cm against 5.61 cm for the plain TIN of the same
   points; the per-cell mean with the TIN only in the empty cells gives 5.80 cm, the TIN
   sampled at every centre 5.69 cm (bilinear resampling of a 1 m lattice loses detail the
   fit puts back).
3. ``method="sample"`` (surface models: the highest return per cell): cells with points
   keep their statistic, the empty cells inside the hull get the TIN of the cells'
   (centre, value) nodes.

Cells with points keep their count and variance (the paper's statistics). Interpolated
cells have count 0, are flagged ``filled`` and carry as variance the mean per-cell
variance of the cells with two or more points (the scatter of the points about a cell's
value), so geolocation uncertainty does not treat them as exact.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..errors import DemError
from .dem import Dem
from .grid import GridSpec

__all__ = ["Coverage", "TinGrid", "bilinear_fit", "grid_cloud", "grid_points_tin", "tin_at"]

_CG_RTOL = 1e-10
_CG_MAXITER = 2000


@dataclass(frozen=True)
class Coverage:
    """How the cells of a gridded point cloud got their values.

    Attributes
    ----------
    cells : int
        All cells of the grid.
    with_points : int
        Cells holding at least one point (the paper's cells).
    interpolated : int
        Cells without a point that got a value from the TIN.
    holes : int
        Cells left without a value (outside the points' hull).
    """

    cells: int
    with_points: int
    interpolated: int
    holes: int

    def percent(self, count: int) -> float:
        """``count`` as a percentage of all cells."""
        return 100.0 * count / self.cells

    def describe(self) -> str:
        """One line: counts and percentages of each kind of cell."""
        return (
            f"{self.with_points:,} cells with points ({self.percent(self.with_points):.1f} %), "
            f"{self.interpolated:,} interpolated ({self.percent(self.interpolated):.1f} %), "
            f"{self.holes:,} holes ({self.percent(self.holes):.1f} %)"
        )

    @classmethod
    def of(cls, dem: Dem) -> Coverage:
        """Coverage of a DEM: count > 0, filled, NaN."""
        return cls(
            int(dem.elevation.size),
            int(np.count_nonzero(dem.count > 0)),
            int(np.count_nonzero(dem.filled & ~dem.nodata)),
            int(np.count_nonzero(dem.nodata)),
        )


@dataclass(frozen=True, eq=False)
class TinGrid:
    """Result of :func:`grid_points_tin`.

    Attributes
    ----------
    dem : Dem
        Elevations (m) at cell centres, count and variance of the points per cell.
    coverage : Coverage
        Cells with points, interpolated, holes.
    """

    dem: Dem
    coverage: Coverage


def tin_at(xy_nodes: np.ndarray, z_nodes: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Barycentric interpolation in the Delaunay triangulation of ``xy_nodes``.

    Parameters
    ----------
    xy_nodes : ndarray, shape (n, 2)
        Node positions (m).
    z_nodes : ndarray, shape (n,)
        Node values (m).
    x, y : ndarray, same shape S
        Query points (m).

    Returns
    -------
    ndarray, float64, shape S
        NaN outside the nodes' convex hull.
    """
    from scipy.spatial import Delaunay, QhullError

    nodes = np.asarray(xy_nodes, dtype=np.float64)
    zn = np.asarray(z_nodes, dtype=np.float64)
    if len(nodes) < 3:
        raise DemError(f"a TIN needs at least 3 points, got {len(nodes)}")
    try:
        tri = Delaunay(nodes)
    except QhullError:
        raise DemError("the points are collinear or coincident: no TIN can be built") from None
    q = np.column_stack([np.ravel(x), np.ravel(y)]).astype(np.float64)
    simplex = tri.find_simplex(q)
    inside = simplex >= 0
    s = np.where(inside, simplex, 0)
    trans = tri.transform[s]  # (m, 3, 2): affine to barycentric coordinates
    b2 = np.einsum("mij,mj->mi", trans[:, :2], q - trans[:, 2])
    bary = np.column_stack([b2, 1.0 - b2.sum(axis=1)])
    z = np.einsum("mi,mi->m", bary, zn[tri.simplices[s]])
    return np.where(inside, z, np.nan).reshape(np.shape(x))


def _needed_cells(grid: GridSpec, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells inside the hull, and cells whose centre is within one cell of it.

    Returns two boolean ``(nrows, ncols)`` masks: centre inside the hull; centre outside
    but within Chebyshev distance ``cell_m`` (the reach of a centre's value in the bilinear
    surface).
    """
    import shapely
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull_xy = xy[ConvexHull(xy).vertices]
    except QhullError:
        raise DemError("the points are collinear or coincident: no TIN can be built") from None
    h = grid.cell_m * (1.0 + 1e-6)  # a centre exactly one cell away still counts
    shifts = np.array([[-h, -h], [-h, h], [h, -h], [h, h]])
    grown_xy = (hull_xy[:, None, :] + shifts[None]).reshape(-1, 2)
    grown_xy = grown_xy[ConvexHull(grown_xy).vertices]
    ex, ny = grid.centres()
    hull = shapely.Polygon(hull_xy)
    grown = shapely.Polygon(grown_xy)
    shapely.prepare(hull)
    shapely.prepare(grown)
    inside = shapely.intersects_xy(hull, ex, ny)
    near = shapely.contains_xy(grown, ex, ny) & ~inside
    return inside, near


def bilinear_fit(
    grid: GridSpec,
    xyz: np.ndarray,
    prior: np.ndarray,
    prior_weight: float,
) -> np.ndarray:
    """Least-squares cell-centre values whose bilinear surface fits the points.

    Minimises ``sum_i (B(p_i) v - z_i)^2 + w * sum_c (v_c - prior_c)^2`` over the cells
    where ``prior`` is finite, ``B(p)`` being the bilinear weights of the four centres
    around ``p`` (the DEM surface of :meth:`Dem.sample`). Solved by conjugate gradients on
    the normal equations (symmetric positive definite for ``w > 0``).

    Parameters
    ----------
    grid : GridSpec
    xyz : ndarray, shape (n, 3)
        Points (m, grid frame); each must have its four surrounding centres where
        ``prior`` is finite.
    prior : ndarray, shape (nrows, ncols)
        Prior cell values (m); NaN = not an unknown (stays NaN).
    prior_weight : float
        ``w`` (> 0).

    Returns
    -------
    ndarray, float64, shape (nrows, ncols)
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import LinearOperator, cg

    if not (np.isfinite(prior_weight) and prior_weight > 0):
        raise DemError(f"prior_weight must be positive, got {prior_weight}")
    active = np.isfinite(prior).ravel()
    index = np.full(active.size, -1, dtype=np.int64)
    index[active] = np.arange(int(active.sum()))
    gx, gy = grid.to_grid(xyz[:, 0], xyz[:, 1])
    c0 = np.clip(np.floor(gx).astype(np.int64), 0, max(grid.ncols - 2, 0))
    r0 = np.clip(np.floor(gy).astype(np.int64), 0, max(grid.nrows - 2, 0))
    fx, fy = gx - c0, gy - r0
    c1 = np.minimum(c0 + 1, grid.ncols - 1)
    r1 = np.minimum(r0 + 1, grid.nrows - 1)
    flat = np.stack(
        [r0 * grid.ncols + c0, r0 * grid.ncols + c1, r1 * grid.ncols + c0, r1 * grid.ncols + c1],
        axis=1,
    )
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    cols = index[flat]
    if (cols < 0).any():
        raise DemError("a point's surrounding cell centres are outside the fitted cells")
    m = len(xyz)
    b = sp.csr_matrix(
        (w.ravel(), (np.repeat(np.arange(m), 4), cols.ravel())),
        shape=(m, int(active.sum())),
    )
    p0 = prior.ravel()[active].astype(np.float64)
    normal = (b.T @ b + prior_weight * sp.identity(b.shape[1], format="csr")).tocsr()
    rhs = b.T @ xyz[:, 2] + prior_weight * p0
    inv_diag = 1.0 / normal.diagonal()
    precond = LinearOperator(normal.shape, matvec=lambda r: inv_diag * r)
    # Solve for the correction to the prior: its scale is the data's misfit (cm to m),
    # not the heights (hundreds of m), so the relative tolerance means something.
    dv, info = cg(normal, rhs - normal @ p0, rtol=_CG_RTOL, maxiter=_CG_MAXITER, M=precond)
    if info != 0:
        raise DemError(f"the TIN fit did not converge (conjugate gradients: {info})")
    out = np.full(active.size, np.nan)
    out[active] = p0 + dv
    return out.reshape(grid.shape)


def grid_points_tin(
    xyz: np.ndarray,
    cell_m: float,
    *,
    bounds: tuple[float, float, float, float] | None = None,
    crs_wkt: str | None = None,
    statistic: Literal["mean", "max"] = "mean",
    method: Literal["fit", "sample"] = "fit",
    prior_weight: float = 0.3,
) -> TinGrid:
    """Grid points with per-cell statistics and a TIN between them.

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        Points (m) in the grid's frame (the site frame); non-finite rows are ignored.
    cell_m : float
        Cell edge (m).
    bounds : (x_min, y_min, x_max, y_max), optional
        Outer grid edges (m); default the points' bounding box (see :meth:`Dem.from_points`).
    crs_wkt : str, optional
        CRS stored with the DEM.
    statistic : {"mean", "max"}
        The cell value where points fall: their mean (terrain) or the highest (surface
        model).
    method : {"fit", "sample"}
        ``"fit"``: bilinear least-squares fit with the TIN as prior (module docstring);
        ``"sample"``: the statistic where points fall, the TIN of the cell values between.
    prior_weight : float
        Weight of the TIN prior per cell for ``method="fit"``, in points.

    Returns
    -------
    TinGrid
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DemError(f"points must have shape (n, 3), got {pts.shape}")
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) < 3:
        raise DemError(f"a TIN needs at least 3 points, got {len(pts)}")
    if bounds is None:
        # One cell of margin: every point then lies inside the hull of cell centres,
        # where the bilinear surface is defined.
        lo, hi = pts[:, :2].min(axis=0) - cell_m, pts[:, :2].max(axis=0) + cell_m
        bounds = (
            float(np.floor(lo[0] / cell_m) * cell_m),
            float(np.floor(lo[1] / cell_m) * cell_m),
            float(np.ceil(hi[0] / cell_m) * cell_m),
            float(np.ceil(hi[1] / cell_m) * cell_m),
        )
    base = Dem.from_points(pts, cell_m, bounds=bounds, crs_wkt=crs_wkt)
    grid = base.grid
    rows, cols = grid.cell_of(pts[:, 0], pts[:, 1])
    # with ``bounds`` given, points outside the grid take no part
    pts, rows, cols = pts[rows >= 0], rows[rows >= 0], cols[rows >= 0]
    if len(pts) < 3:
        raise DemError(f"only {len(pts)} point(s) inside the grid bounds; a TIN needs 3")
    has = base.count > 0
    value = np.array(base.elevation, dtype=np.float64)
    if statistic == "max":
        top = np.full(grid.nrows * grid.ncols, -np.inf)
        np.maximum.at(top, rows * grid.ncols + cols, pts[:, 2])
        value = np.where(has, top.reshape(grid.shape), np.nan)
    elif statistic != "mean":
        raise DemError(f"statistic must be 'mean' or 'max', got {statistic!r}")
    if method not in ("fit", "sample"):
        raise DemError(f"method must be 'fit' or 'sample', got {method!r}")
    ex, ny = grid.centres()
    if method == "fit":
        nodes_xy, nodes_z = pts[:, :2], pts[:, 2]
    else:
        nodes_xy = np.column_stack([ex[has], ny[has]])
        nodes_z = value[has]
    inside, near = _needed_cells(grid, nodes_xy)
    prior = np.full(grid.shape, np.nan)
    prior[inside] = tin_at(nodes_xy, nodes_z, ex[inside], ny[inside])
    # Centres a hair outside the triangulation (round-off at the hull) or in the one-cell
    # band around it: the nearest node's value.
    edge = (inside & np.isnan(prior)) | near
    if edge.any():
        _, nearest = cKDTree(nodes_xy).query(np.column_stack([ex[edge], ny[edge]]))
        prior[edge] = nodes_z[nearest]
    if method == "fit":
        gx, gy = grid.to_grid(pts[:, 0], pts[:, 1])
        on = (gx >= 0) & (gx <= grid.ncols - 1) & (gy >= 0) & (gy <= grid.nrows - 1)
        elev = bilinear_fit(grid, pts[on], prior, prior_weight)
    else:
        elev = np.where(has, value, prior)
    interpolated = ~has & np.isfinite(elev)
    multi = base.count >= 2
    fill_var = float(np.mean(base.variance[multi])) if multi.any() else 0.0
    var = np.where(has, base.variance, np.where(interpolated, fill_var, np.nan))
    dem = replace(
        base,
        elevation=elev.astype(np.float32),
        variance=var.astype(np.float32),
        filled=interpolated,
    )
    return TinGrid(dem, Coverage.of(dem))


def grid_cloud(
    xyz: np.ndarray,
    cell_m: float,
    *,
    interpolate: Literal["tin", "none"],
    surface: Literal["dtm", "dsm"] = "dtm",
    bounds: tuple[float, float, float, float] | None = None,
    crs_wkt: str | None = None,
) -> Dem:
    """A DEM of a point cloud: a terrain (mean) or surface (highest) model, TIN or not.

    ``interpolate="tin"``: :func:`grid_points_tin` (a fit for a terrain model, the
    highest point per cell and a TIN between for a surface model); ``"none"``: the
    per-cell statistics only (:meth:`Dem.from_points`), holes where no point falls.
    """
    if interpolate == "none":
        return Dem.from_points(xyz, cell_m, bounds=bounds, crs_wkt=crs_wkt)
    dsm = surface == "dsm"
    return grid_points_tin(
        xyz,
        cell_m,
        bounds=bounds,
        crs_wkt=crs_wkt,
        statistic="max" if dsm else "mean",
        method="sample" if dsm else "fit",
    ).dem
