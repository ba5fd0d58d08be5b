"""Benchmark: a sparse real lidar tile gridded at 1 m, 10 % of its ground points held out.

The tile's ground points (ASPRS class 2) are converted exactly into a local frame
anchored at the tile's centre; 10 % of them (fixed seed) are held out. The kept points
are gridded by demtrack (per-cell statistics, the TIN between them, the bilinear fit;
:mod:`demtrack.core.terrain.tin`) and, as the peer, interpolated by a plain scipy
Delaunay TIN (``LinearNDInterpolator``) of the same kept points. Both are evaluated at
the held-out points inside the kept points' hull; printed: point density, hole share
with and without the TIN, both RMSEs and their ratio (demtrack / peer, < 1 is better).
The per-cell mean alone (``--interpolate none``) is shown too.

The tile: ``autzen_trim.laz`` from laspy's source distribution on the package registry::

    pip download --no-deps --no-binary :all: laspy==2.7.0
    tar xzf laspy-2.7.0.tar.gz laspy-2.7.0/tests/data/autzen_trim.laz

Usage: ``demtrack bench lidar-holdout FILE.laz [--cell 1] [--holdout 0.1] [--seed 0]``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Holdout", "holdout_comparison", "main"]


@dataclass(frozen=True)
class Holdout:
    """Figures of one held-out comparison (heights in m, local frame).

    Attributes
    ----------
    n_ground, n_held, n_inside : int
        Ground points, held-out points, held-out points inside the kept points' hull.
    n_valued, n_valued_mean : int
        Held-out points inside the hull where demtrack's DEM has a value, and where the
        per-cell mean alone has one.
    density_per_m2 : float
        Kept ground points per m^2 over their hull.
    holes_pct_none, holes_pct_tin : float
        Share of the grid's cells that are holes, without and with the TIN.
    rmse_tin_m, rmse_peer_m, rmse_mean_m : float
        Held-out RMSE of demtrack's TIN grid, of the plain scipy TIN, and of the per-cell
        mean alone (over the points where it has a value).
    coverage : str
        demtrack's coverage line.
    """

    n_ground: int
    n_held: int
    n_inside: int
    n_valued: int
    n_valued_mean: int
    density_per_m2: float
    holes_pct_none: float
    holes_pct_tin: float
    rmse_tin_m: float
    rmse_peer_m: float
    rmse_mean_m: float
    coverage: str


def holdout_comparison(
    path: str | Path, *, cell_m: float = 1.0, holdout: float = 0.1, seed: int = 0
) -> Holdout:
    """Run the comparison on a classified LAS/LAZ file."""
    from scipy.interpolate import LinearNDInterpolator
    from scipy.spatial import ConvexHull

    from demtrack.core.terrain.cloud_site import anchor_for_cloud, cloud_crs, select_surface
    from demtrack.core.terrain.crs_import import points_to_local
    from demtrack.core.terrain.dem import Dem
    from demtrack.core.terrain.pointcloud import read_point_cloud
    from demtrack.core.terrain.tin import grid_points_tin

    cloud = read_point_cloud(path)
    crs = cloud_crs(cloud)
    ground = select_surface(cloud, "dtm", str(path))
    frame = anchor_for_cloud(ground.xyz, crs)
    e, n, u = points_to_local(*ground.xyz.T, crs.crs_wkt, frame, z_unit_m=crs.z_unit_m)
    hold = np.random.default_rng(seed).uniform(size=len(e)) < holdout
    kept = np.column_stack([e[~hold], n[~hold], u[~hold]])
    tin = grid_points_tin(kept, cell_m)
    mean = Dem.from_points(kept, cell_m, bounds=tin.dem.grid.bounds)
    peer = LinearNDInterpolator(kept[:, :2], kept[:, 2])(e[hold], n[hold])
    inside = np.isfinite(peer)
    z_tin = tin.dem.sample(e[hold], n[hold])
    z_mean = mean.sample(e[hold], n[hold])
    truth = u[hold]
    valued = inside & np.isfinite(z_tin)
    on_mean = inside & np.isfinite(z_mean)

    def rmse(z: np.ndarray, ok: np.ndarray) -> float:
        return float(np.sqrt(np.mean((z[ok] - truth[ok]) ** 2))) if ok.any() else float("nan")

    return Holdout(
        len(e),
        int(hold.sum()),
        int(inside.sum()),
        int(valued.sum()),
        int(on_mean.sum()),
        len(kept) / float(ConvexHull(kept[:, :2]).volume),
        100.0 * float(mean.nodata.mean()),
        100.0 * float(tin.dem.nodata.mean()),
        rmse(z_tin, valued),
        rmse(peer, inside),
        rmse(z_mean, on_mean),
        tin.coverage.describe(),
    )


def main(argv: list[str] | None = None) -> int:
    """Print the comparison; returns the exit status."""
    p = argparse.ArgumentParser(
        prog="demtrack bench lidar-holdout", description=__doc__.split("\n")[0]
    )
    p.add_argument("points", type=Path, help="classified LAS/LAZ (e.g. autzen_trim.laz)")
    p.add_argument("--cell", type=float, default=1.0, help="cell size, m (default 1)")
    p.add_argument("--holdout", type=float, default=0.1, help="share held out (default 0.1)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    r = holdout_comparison(args.points, cell_m=args.cell, holdout=args.holdout, seed=args.seed)
    print(f"{args.points}: {r.n_ground:,} ground points, {r.density_per_m2:.2f} per m^2 (kept)")
    print(f"  grid {args.cell:g} m: {r.coverage}")
    print(f"  holes: {r.holes_pct_none:.1f} % per-cell mean only, {r.holes_pct_tin:.1f} % with TIN")
    print(
        f"  held out {r.n_held:,}, {r.n_inside:,} inside the hull, {r.n_valued:,} of them "
        "valued by demtrack"
    )
    print(f"  {'model':<34}{'points':>8}{'held-out RMSE':>15}{'vs peer':>9}")
    for name, k, v in (
        ("demtrack TIN grid (bilinear fit)", r.n_valued, r.rmse_tin_m),
        ("scipy Delaunay TIN (peer)", r.n_inside, r.rmse_peer_m),
        ("per-cell mean only (where valued)", r.n_valued_mean, r.rmse_mean_m),
    ):
        print(f"  {name:<34}{k:>8,}{100 * v:>12.2f} cm{v / r.rmse_peer_m:>9.3f}")
    return 0
