"""``demtrack build-dem``: grid a laser point cloud into a DEM GeoTIFF (Collins et al.)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from demtrack.core.crs_import import local_crs_wkt, points_to_local, read_raster_to_local
from demtrack.core.dem import VERTICAL_DATUM_LOCAL, Dem
from demtrack.core.errors import CrsError, InputFileError
from demtrack.core.geodesy import as_crs
from demtrack.core.site import load_site

__all__ = ["read_points", "register"]


def read_points(path: Path) -> np.ndarray:
    """Points ``(n, 3)`` from ``.npy`` (an (n, 3) array) or ``.csv`` (x, y, z columns)."""
    suffix = path.suffix.lower()
    if not path.is_file():
        raise InputFileError(f"point file not found: {path}")
    try:
        if suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        elif suffix in (".csv", ".txt", ".xyz"):
            with path.open(encoding="utf-8") as fh:
                first = fh.readline()
            header = any(c.isalpha() for c in first.replace("e", "").replace("E", ""))
            pts = np.loadtxt(
                path,
                delimiter="," if "," in first else None,
                skiprows=1 if header else 0,
                usecols=(0, 1, 2),
                ndmin=2,
            )
        else:
            raise InputFileError(
                f"unsupported point file {path.name}: use .npy or .csv (LAS/LAZ is planned)"
            )
    except ValueError as exc:
        raise InputFileError(f"malformed point file {path}: {str(exc).splitlines()[0]}") from None
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise InputFileError(f"{path}: points must be an (n, 3) array of x, y, z; got {pts.shape}")
    if len(pts) == 0:
        raise InputFileError(f"{path}: no points")
    return pts[:, :3]


def _run(args: argparse.Namespace) -> int:
    pts = read_points(args.points)
    bounds = tuple(args.bounds) if args.bounds else None
    if args.site is not None:
        site = load_site(args.site)
        if args.crs:
            e, n, u = points_to_local(
                pts[:, 0],
                pts[:, 1],
                pts[:, 2],
                args.crs,
                site.frame,
                geoid_undulation_m=site.geoid_undulation_m,
            )
            pts = np.column_stack([e, n, u])
        crs_wkt = local_crs_wkt(site.frame)
    elif args.crs:
        crs = as_crs(args.crs)
        if not crs.is_projected:
            raise CrsError(
                f"--crs {args.crs} is not a projected CRS in metres; grid in a site "
                "frame with --site DIR instead"
            )
        crs_wkt = crs.to_wkt()
    else:
        raise CrsError(
            "the points' CRS is missing: pass --site DIR (points in the site frame, "
            "or with --crs converted into it) or --crs EPSG:XXXX"
        )
    dem = Dem.from_points(pts, args.cell, bounds=bounds, crs_wkt=crs_wkt)
    holes = int(dem.nodata.sum())
    if args.fill is not None:
        coarse_dem = Dem.read(args.fill)
        same_crs = coarse_dem.crs_wkt is not None and as_crs(coarse_dem.crs_wkt) == as_crs(crs_wkt)
        if args.site is not None and not (
            same_crs and coarse_dem.vertical_datum == VERTICAL_DATUM_LOCAL
        ):
            # Another CRS, or heights above a datum: warp into the site frame exactly.
            coarse = read_raster_to_local(
                args.fill, site.frame, dem.grid, geoid_undulation_m=site.geoid_undulation_m
            )
            coarse_dem = Dem(dem.grid, coarse)
        elif not same_crs:
            raise CrsError(f"{args.fill} is not in {args.crs}; pass --site to warp it")
        dem = dem.fill_holes(coarse_dem, coarse_sigma_m=args.fill_sigma)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    dem.write(args.output)
    g = dem.grid
    print(
        f"{args.output}: {g.ncols}x{g.nrows} cells of {g.cell_m} m from {len(pts):,} points; "
        f"{100 * dem.coverage:.1f} % of cells hold points, {holes:,} holes"
        + (f", {int(dem.filled.sum()):,} filled from {args.fill}" if args.fill else "")
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``build-dem`` command."""
    p = sub.add_parser("build-dem", help="grid laser points into a DEM GeoTIFF")
    p.add_argument("points", type=Path, help="points: .npy (n x 3) or .csv with x,y,z")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DEM.tif")
    p.add_argument("--cell", type=float, default=0.5, help="cell size in m (default 0.5)")
    p.add_argument(
        "--fill",
        type=Path,
        metavar="COARSE.tif",
        help="fill holes by bilinear interpolation of this coarser DEM",
    )
    p.add_argument(
        "--fill-sigma",
        type=float,
        default=1.0,
        metavar="M",
        help="1-sigma error assumed for the coarse DEM (default 1 m)",
    )
    p.add_argument("--bounds", type=float, nargs=4, metavar=("XMIN", "YMIN", "XMAX", "YMAX"))
    p.add_argument("--site", type=Path, metavar="DIR", help="grid in this site's frame")
    p.add_argument("--crs", help="CRS of the points (EPSG code, WKT or PROJ string)")
    p.set_defaults(func=_run)
