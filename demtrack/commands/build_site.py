"""``demtrack build-dem POINTS --new-site DIR``: a site from a point cloud alone.

The cloud's CRS comes from the file (WKT or GeoTIFF keys) or ``--crs``; its units may be
metres, international or US survey feet, or degrees. The frame is anchored at the
cloud's centre on the ground (WGS84 ellipsoidal height). The site is built in a
temporary folder beside DIR and renamed into place, so a refused input leaves nothing.
"""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from demtrack.core.errors import InputFileError, SiteError

if TYPE_CHECKING:
    from demtrack.core.geo.geoid import GeoidModel

__all__ = ["run_new_site"]

_Z_UNITS = {"m": 1.0, "ft": 0.3048, "ftUS": 1200.0 / 3937.0}


def _check_options(args: argparse.Namespace) -> tuple[GeoidModel, Path | None]:
    """The geoid the heights are converted with (and a user's grid file to copy in)."""
    from demtrack.core.geo.geoid import GeoidModel

    from .site_import import _geoid_choice

    root: Path = args.new_site
    if args.output is not None or args.site is not None:
        raise InputFileError("--new-site writes DIR/dem.tif; leave out -o and --site")
    if args.fill is not None:
        raise InputFileError("--fill is not used with --new-site (the TIN fills the gaps)")
    if root.exists() and (not root.is_dir() or any(root.iterdir())):
        raise SiteError(f"{root} exists and is not an empty folder; --new-site makes a new one")
    if args.vertical_datum is None:
        raise InputFileError(
            "--new-site needs --vertical-datum ellipsoidal|orthometric: what the points' "
            "heights are measured from"
        )
    given, n_given = args.geoid, args.geoid_undulation
    if given is not None and n_given is not None:
        raise InputFileError("give either --geoid or --geoid-undulation, not both")
    if args.vertical_datum == "orthometric":
        if n_given is not None:
            return GeoidModel.constant(float(n_given)), None
        if given is None:
            raise InputFileError(
                "orthometric heights need the site's geoid: --geoid egm96|FILE "
                "(evaluated per point) or --geoid-undulation N (m, h = H + N)"
            )
        geoid, grid_file = _geoid_choice(given, root)
        if not geoid.orthometric:
            raise InputFileError("--vertical-datum orthometric needs a geoid, not --geoid none")
        return geoid, grid_file
    if n_given not in (None, 0.0):
        raise InputFileError(
            "--geoid-undulation is for --vertical-datum orthometric; ellipsoidal heights "
            "are used as they are"
        )
    if given is not None:  # the site states it for later imports and exports
        return _geoid_choice(given, root)
    return GeoidModel.ellipsoidal(), None


def run_new_site(args: argparse.Namespace) -> int:
    """Create the site folder ``args.new_site`` from ``args.points``."""
    import numpy as np
    from scipy.spatial import ConvexHull, QhullError

    from demtrack.core.geo.geoid import GeoidModel
    from demtrack.core.site.folder import vertical_datum_doc
    from demtrack.core.site.update import new_manifest, write_dem_atomic, write_manifest
    from demtrack.core.terrain.cloud_site import anchor_for_cloud, cloud_crs, select_surface
    from demtrack.core.terrain.crs_import import local_crs_wkt, points_to_local
    from demtrack.core.terrain.pointcloud import read_point_cloud
    from demtrack.core.terrain.tin import Coverage, grid_cloud

    geoid, grid_file = _check_options(args)
    n_geoid = geoid if args.vertical_datum == "orthometric" else 0.0
    root: Path = args.new_site
    surface = args.surface or "dtm"
    interpolate = args.interpolate or "tin"
    cell = 1.0 if args.cell is None else args.cell
    cloud = read_point_cloud(args.points)
    crs = cloud_crs(cloud, args.crs, _Z_UNITS[args.z_unit] if args.z_unit else None)
    cloud = select_surface(cloud, surface, str(args.points))
    cloud = cloud.select(ground_only=args.ground_only, first_returns=args.first_returns)
    if len(cloud) == 0:
        raise InputFileError(f"{args.points}: no points left after the class/return selection")
    frame = anchor_for_cloud(cloud.xyz, crs, geoid_undulation_m=n_geoid)
    e, n, u = points_to_local(
        *cloud.xyz.T, crs.crs_wkt, frame, geoid_undulation_m=n_geoid, z_unit_m=crs.z_unit_m
    )
    pts = np.column_stack([e, n, u])
    bounds = tuple(args.bounds) if args.bounds else None
    wkt = local_crs_wkt(frame)
    dem = grid_cloud(
        pts, cell, interpolate=interpolate, surface=surface, bounds=bounds, crs_wkt=wkt
    )
    if dem.nodata.all():
        raise InputFileError(f"{args.points}: no point falls inside --bounds {bounds}")
    try:
        area_m2 = float(ConvexHull(pts[:, :2]).volume)
    except QhullError:
        area_m2 = float("nan")
    tmp = root.parent / f".{root.name}.building-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        write_dem_atomic(tmp / "dem.tif", dem)
        doc = new_manifest(args.name or root.name, frame, 0.0)
        if grid_file is not None:
            (tmp / "geoid").mkdir()
            shutil.copyfile(grid_file, tmp / "geoid" / grid_file.name)
            geoid = GeoidModel.from_grid(tmp / "geoid" / grid_file.name, geoid.name)
        doc["vertical_datum"] = vertical_datum_doc(geoid, tmp)  # relative: same once renamed
        doc["geoid_undulation_m"] = round(
            float(geoid.undulation_m(frame.lat_deg, frame.lon_deg)), 3
        )
        write_manifest(tmp, doc)
        if root.exists():
            root.rmdir()  # checked empty above
        tmp.rename(root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    g = dem.grid
    lo, hi = dem.elevation_range()
    datum = (
        f"orthometric, h = H + N with N from {geoid.description}"
        if args.vertical_datum == "orthometric"
        else "ellipsoidal (WGS84)"
    )
    print(
        f"{root}: new site from {args.points}; DEM {g.ncols}x{g.nrows} cells of {g.cell_m:g} m, "
        f"E {g.x_min:.1f} .. {g.x_max:.1f}, N {g.y_min:.1f} .. {g.y_max:.1f} m; "
        f"Z {lo:.2f} .. {hi:.2f} m (local frame)"
    )
    print(
        f"  frame anchor lat {frame.lat_deg:.7f} lon {frame.lon_deg:.7f} h {frame.h_m:.3f} m "
        "(WGS84 ellipsoidal; the cloud's centre, on the ground)"
    )
    print(
        f"  points: {crs.name}, horizontal unit {crs.xy_unit} ({crs.xy_unit_m:.10g} m), "
        f"height unit {crs.z_unit_m:.10g} m; heights {datum}"
    )
    density = len(pts) / area_m2 if area_m2 > 0 else float("nan")
    kind = (
        "DTM: ground points (class 2)"
        if surface != "dsm"
        else "DSM: first returns, highest per cell"
    )
    print(
        f"  {kind}: {len(pts):,} points, {density:.2f} per m^2 over their hull; "
        f"interpolate {interpolate}"
    )
    print(f"  {Coverage.of(dem).describe()}")
    return 0
