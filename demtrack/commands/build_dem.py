"""``demtrack build-dem``: grid a laser point cloud into a DEM GeoTIFF (Collins et al.).

With ``--new-site DIR`` it creates a site from the cloud alone (any CRS, any unit): the
frame is anchored at the cloud's centre on the ground, the DEM gridded in it (per-cell
statistics, a TIN between the points), and the folder written beside DIR first, then
renamed, so a refused input leaves nothing behind.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from demtrack.core.errors import CrsError, InputFileError

from .common import positive, require_suffix

__all__ = ["register"]


def _source_vertical_datum(crs: object) -> str:
    """The vertical datum of points kept in their own CRS, as the CRS states it."""
    for sub in getattr(crs, "sub_crs_list", None) or []:
        if sub.is_vertical:
            return f"heights of the source points: {sub.name}"
    return "heights of the source points (their CRS states no vertical datum)"


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    if args.new_site is not None:
        from .build_site import run_new_site

        return run_new_site(args)
    if args.output is None:
        raise InputFileError("give -o DEM.tif, or --new-site DIR to create a site")
    for flag in ("vertical_datum", "geoid", "geoid_undulation", "z_unit", "name"):
        if getattr(args, flag) is not None:
            raise InputFileError(f"--{flag.replace('_', '-')} is for --new-site")

    from demtrack.core.geo.geodesy import as_crs
    from demtrack.core.site.folder import load_site
    from demtrack.core.site.update import write_dem_atomic
    from demtrack.core.terrain.crs_import import (
        local_crs_wkt,
        points_to_local,
        read_raster_to_local,
    )
    from demtrack.core.terrain.dem import VERTICAL_DATUM_LOCAL, Dem
    from demtrack.core.terrain.pointcloud import read_point_cloud

    require_suffix(args.output, (".tif", ".tiff"), "--output")
    cell = 0.5 if args.cell is None else args.cell
    cloud = read_point_cloud(args.points)
    if args.surface is not None:
        from demtrack.core.terrain.cloud_site import select_surface

        cloud = select_surface(cloud, args.surface, str(args.points))
    cloud = cloud.select(ground_only=args.ground_only, first_returns=args.first_returns)
    if len(cloud) == 0:
        raise InputFileError(f"{args.points}: no points left after the class/return selection")
    pts = cloud.xyz
    points_crs = args.crs or cloud.crs_wkt
    bounds = tuple(args.bounds) if args.bounds else None
    if args.site is not None:
        site = load_site(args.site)
        # The points' heights: h = z + N with a site's stated constant N, as before; a site
        # whose datum is a geoid grid (EGM96) takes them as ellipsoidal (nothing here says
        # they are orthometric), as it did when such sites stated N = 0.
        points_n = site.geoid_undulation_m if site.geoid.kind == "constant" else 0.0
        if points_crs:
            e, n, u = points_to_local(
                pts[:, 0],
                pts[:, 1],
                pts[:, 2],
                points_crs,
                site.frame,
                geoid_undulation_m=points_n,
            )
            pts = np.column_stack([e, n, u])
        crs_wkt = local_crs_wkt(site.frame)
    elif points_crs:
        crs = as_crs(points_crs)
        unit = crs.axis_info[0].unit_name if crs.axis_info else ""
        if not crs.is_projected or unit not in ("metre", "meter"):
            raise CrsError(
                f"the points' CRS {crs.name!r} is not projected in metres; grid them in a "
                "site frame with --site DIR, or make a new site with --new-site DIR"
            )
        crs_wkt = crs.to_wkt()
        vertical_datum = _source_vertical_datum(crs)
    else:
        raise CrsError(
            "the points' CRS is missing: pass --site DIR (points in the site frame, "
            "or with --crs converted into it) or --crs EPSG:XXXX"
        )
    from demtrack.core.terrain.tin import grid_cloud

    dem = grid_cloud(
        pts,
        cell,
        interpolate="tin" if args.interpolate == "tin" else "none",
        surface="dsm" if args.surface == "dsm" else "dtm",
        bounds=bounds,
        crs_wkt=crs_wkt,
    )
    if args.site is None:
        # Heights stay those of the points: say so instead of claiming the site's datum.
        dem = dataclasses.replace(dem, vertical_datum=vertical_datum)
    holes = int(dem.nodata.sum())
    if args.fill is not None:
        coarse_dem = Dem.read(args.fill)
        same_crs = coarse_dem.crs_wkt is not None and as_crs(coarse_dem.crs_wkt) == as_crs(crs_wkt)
        if args.site is not None and not (
            same_crs and coarse_dem.vertical_datum == VERTICAL_DATUM_LOCAL
        ):
            # Another CRS, or heights above a datum: warp into the site frame exactly.
            coarse = read_raster_to_local(
                args.fill, site.frame, dem.grid, geoid_undulation_m=points_n
            )
            coarse_dem = Dem(dem.grid, coarse)
        elif not same_crs:
            raise CrsError(f"{args.fill} is not in {args.crs}; pass --site to warp it")
        dem = dem.fill_holes(coarse_dem, coarse_sigma_m=args.fill_sigma)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_dem_atomic(args.output, dem)  # a failed write leaves no partial file
    g = dem.grid
    if args.interpolate == "tin":
        from demtrack.core.terrain.tin import Coverage

        print(
            f"{args.output}: {g.ncols}x{g.nrows} cells of {g.cell_m} m from {len(pts):,} "
            f"points; {Coverage.of(dem).describe()}"
        )
        return 0
    print(
        f"{args.output}: {g.ncols}x{g.nrows} cells of {g.cell_m} m from {len(pts):,} points; "
        f"{100 * dem.coverage:.1f} % of cells hold points, {holes:,} holes"
        + (f", {int(dem.filled.sum()):,} filled from {args.fill}" if args.fill else "")
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``build-dem`` command."""
    p = sub.add_parser("build-dem", help="grid laser points into a DEM GeoTIFF")
    p.add_argument("points", type=Path, help="points: .las/.laz, .npy (n x 3) or .csv x,y,z")
    p.add_argument("-o", "--output", type=Path, metavar="DEM.tif")
    p.add_argument(
        "--new-site",
        type=Path,
        metavar="DIR",
        help="create a site from the points alone (frame anchored at the cloud's centre)",
    )
    p.add_argument(
        "--surface",
        choices=("dtm", "dsm"),
        help="dtm: ground points (class 2), cell mean; dsm: first returns, highest per "
        "cell (default: dtm for --new-site, else every point)",
    )
    p.add_argument(
        "--interpolate",
        choices=("tin", "none"),
        help="tin: a TIN between the points (default for --new-site); none: the cells "
        "with points only, the rest holes (default otherwise)",
    )
    p.add_argument(
        "--vertical-datum",
        choices=("ellipsoidal", "orthometric"),
        help="--new-site: what the points' heights are measured from (orthometric: "
        "h = H + N with --geoid egm96|FILE or --geoid-undulation N)",
    )
    p.add_argument(
        "--geoid",
        metavar="egm96|FILE|none",
        help="--new-site: the site's geoid, evaluated per point (EGM96 from proj-data's "
        "egm96_15.gtx, or a PROJ-readable grid file, copied into the site)",
    )
    p.add_argument("--geoid-undulation", type=float, metavar="N", help="N (m), --new-site")
    p.add_argument("--z-unit", choices=("m", "ft", "ftUS"), help="height unit (default: the CRS's)")
    p.add_argument("--name", help="site name (--new-site; default the folder's name)")
    p.add_argument("--cell", type=positive, help="cell size in m (default 0.5; 1 with --new-site)")
    p.add_argument(
        "--fill",
        type=Path,
        metavar="COARSE.tif",
        help="fill holes by bilinear interpolation of this coarser DEM",
    )
    p.add_argument(
        "--fill-sigma",
        type=positive,
        default=1.0,
        metavar="M",
        help="1-sigma error assumed for the coarse DEM (default 1 m)",
    )
    p.add_argument("--bounds", type=float, nargs=4, metavar=("XMIN", "YMIN", "XMAX", "YMAX"))
    p.add_argument("--site", type=Path, metavar="DIR", help="grid in this site's frame")
    p.add_argument(
        "--crs", help="CRS of the points (EPSG code, WKT or PROJ string); LAS/LAZ state their own"
    )
    p.add_argument(
        "--ground-only", action="store_true", help="LAS/LAZ: ground points only (class 2)"
    )
    p.add_argument(
        "--first-returns", action="store_true", help="LAS/LAZ: first returns only (a surface)"
    )
    p.set_defaults(func=_run)
