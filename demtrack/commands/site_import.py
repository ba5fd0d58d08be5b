"""``demtrack import-dem | import-ortho | import-roads | add-camera``: build a real site.

Each command reads the user's data in its own CRS, converts it exactly into the site
frame, and writes into the site folder atomically (temporary file + rename; ``site.json``
last), so a refused input leaves the site as it was. See ``docs/site-format.md``.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

from demtrack.core.errors import CameraError, SiteError

from .common import finite, non_negative, positive, positive_int

if TYPE_CHECKING:
    from demtrack.core.camera.pinhole import Intrinsics
    from demtrack.core.camera.pose import SurveyedPose
    from demtrack.core.geo.geoid import GeoidModel
    from demtrack.core.site.folder import Site
    from demtrack.core.terrain.dem_import import DemImport

__all__ = ["register"]

_Z_UNITS = {"m": 1.0, "ft": 0.3048, "ftUS": 1200.0 / 3937.0}
_MAX_ORTHO_SIDE = 8192
# core.terrain.crs_import.RESAMPLING_METHODS, without importing the engine at start-up
_RESAMPLING = ("bilinear", "cubic", "nearest", "average")


def _geoid(
    args: argparse.Namespace, doc: dict | None, root: Path
) -> tuple[GeoidModel, Path | None]:
    """The site's geoid model, and a user's grid file to copy into a new site.

    An existing site keeps its own (``--geoid`` / ``--geoid-undulation`` may only repeat
    it); a new site takes ``--geoid egm96|FILE|none`` or ``--geoid-undulation N``
    (neither: none, ellipsoidal). A missing grid is an error naming it.
    """
    from demtrack.core.geo.geoid import GeoidModel
    from demtrack.core.site.folder import load_site

    given, n_given = args.geoid, args.geoid_undulation
    if given is not None and n_given is not None:
        raise SiteError("give either --geoid or --geoid-undulation, not both")
    if doc is not None:
        site_geoid = load_site(root).geoid
        if n_given is not None and GeoidModel.constant(n_given) != site_geoid:
            raise SiteError(
                f"site.json states its geoid as {site_geoid.datum}; --geoid-undulation "
                f"{n_given} would disagree with what is already in the site (edit site.json "
                "to change it)"
            )
        if given is not None and _geoid_choice(given, root)[0] != site_geoid:
            raise SiteError(
                f"site.json states its geoid as {site_geoid.datum}; --geoid {given} would "
                "disagree with what is already in the site (edit site.json to change it)"
            )
        return site_geoid, None
    if n_given is not None:
        return GeoidModel.constant(n_given), None
    if given is None:
        return GeoidModel.ellipsoidal(), None
    return _geoid_choice(given, root)


def _geoid_choice(given: str, root: Path) -> tuple[GeoidModel, Path | None]:
    from demtrack.core.geo.geoid import GeoidModel

    if given.lower() == "none":
        return GeoidModel.ellipsoidal(), None
    if given.lower() == "egm96":
        return GeoidModel.egm96(), None
    path = Path(given)
    if not path.is_file():
        raise SiteError(f"--geoid: geoid grid not found: {path} (use egm96, none or a grid file)")
    inside = root / "geoid" / path.name
    if inside.is_file() and inside.resolve() == path.resolve():
        return GeoidModel.from_grid(inside), None
    return GeoidModel.from_grid(path), path


def _n_at(site_geoid: GeoidModel, x: float, y: float, crs: object) -> float:
    """The site's geoid undulation (m) at a position in ``crs`` (per point for a grid)."""
    if site_geoid.kind != "grid":
        return site_geoid.n_m
    from demtrack.core.geo.geodesy import cached_transformer, horizontal_crs

    hcrs = horizontal_crs(crs)
    lon, lat = cached_transformer(hcrs.to_wkt(), "EPSG:4326").transform(x, y)
    return float(site_geoid.undulation_m(lat, lon))


# --------------------------------------------------------------------------- import-dem


def _run_import_dem(args: argparse.Namespace) -> int:
    from demtrack.core.geo.geodesy import LocalFrame
    from demtrack.core.geo.geoid import GeoidModel
    from demtrack.core.site.folder import MANIFEST, load_site, vertical_datum_doc
    from demtrack.core.site.update import (
        new_manifest,
        read_manifest,
        write_atomic,
        write_dem_atomic,
        write_manifest,
    )
    from demtrack.core.terrain.crs_import import local_crs_wkt
    from demtrack.core.terrain.dem_import import (
        crop_import,
        footprint_bounds_local,
        grid_over,
        import_dem,
        largest_data_rectangle,
        native_cell_m,
        read_raster_info,
        sub_grid,
        suggest_frame,
    )
    from demtrack.core.terrain.grid import GridSpec

    root: Path = args.site
    exists = (root / MANIFEST).is_file()
    doc = read_manifest(root) if exists else None
    infos = [read_raster_info(p) for p in args.tiles]
    geoid, grid_file = _geoid(args, doc, root)
    if args.vertical_datum == "orthometric" and not geoid.orthometric:
        raise SiteError(
            "--vertical-datum orthometric needs the tiles' geoid: --geoid egm96|FILE or "
            "--geoid-undulation N (a new site), or a site.json that states one"
        )
    n_used = geoid if args.vertical_datum == "orthometric" else 0.0
    z_unit = _Z_UNITS[args.z_unit] if args.z_unit else None
    if doc is not None:
        if args.anchor is not None:
            raise SiteError("--anchor is for a new site; this site already has its frame")
        frame = load_site(root).frame
    elif args.anchor is not None:
        frame = LocalFrame(*args.anchor)
    else:
        frame = suggest_frame(infos, geoid_undulation_m=n_used, z_unit_m=z_unit)
    old_grid = None
    if doc is not None and args.cell is None and args.bounds is None:
        old_grid = load_site(root).dem.grid

    def run_import(grid: GridSpec) -> DemImport:
        return import_dem(
            args.tiles,
            frame,
            grid,
            coarse=args.coarse,
            geoid_undulation_m=n_used,
            z_unit_m=z_unit,
            sigma_m=args.sigma,
            coarse_sigma_m=args.coarse_sigma,
            crs_wkt=local_crs_wkt(frame),
            resampling=args.resampling,
        )

    if old_grid is not None:
        grid = old_grid
        bounds_note = "the site's existing grid"
        result = run_import(grid)
    elif args.bounds:
        cell = args.cell or round(min(native_cell_m(i, frame) for i in infos), 3)
        grid = GridSpec.covering(*args.bounds, cell)
        bounds_note = "--bounds as given"
        result = run_import(grid)
    else:
        cell = args.cell or round(min(native_cell_m(i, frame) for i in infos), 3)
        box = grid_over(footprint_bounds_local(infos, frame), cell)
        full = run_import(box)
        # The warped footprint is not axis-aligned in the site frame: its bounding box
        # would leave hole strips along the edges. Keep the largest rectangle inside it.
        r0, r1, c0, c1 = largest_data_rectangle(~full.dem.nodata)
        grid = sub_grid(box, r0, r1, c0, c1)
        cut = box.nrows * box.ncols - grid.nrows * grid.ncols
        bounds_note = (
            "the footprint's bounding box (no edge holes to cut)"
            if cut == 0
            else "the largest rectangle inside the warped footprint (the bounding box "
            f"would add {cut:,} cells, {100 * cut / (box.nrows * box.ncols):.1f} %, along "
            "the edges)"
        )
        result = crop_import(full, r0, r1, c0, c1)
    created = not root.exists()
    root.mkdir(parents=True, exist_ok=True)
    try:
        write_dem_atomic(root / "dem.tif", result.dem)
        if doc is None:
            doc = new_manifest(args.name or root.name, frame, 0.0)
            if grid_file is not None:
                (root / "geoid").mkdir(exist_ok=True)
                copy = root / "geoid" / grid_file.name
                write_atomic(copy, lambda p: shutil.copyfile(grid_file, p))
                geoid = GeoidModel.from_grid(copy, geoid.name)
            doc["vertical_datum"] = vertical_datum_doc(geoid, root)
            n0 = geoid.undulation_m(frame.lat_deg, frame.lon_deg)
            doc["geoid_undulation_m"] = round(float(n0), 3)
        doc["dem"] = "dem.tif"
        write_manifest(root, doc)
    except BaseException:
        if created and not any(root.iterdir()):
            root.rmdir()
        raise
    g = grid
    dem = result.dem
    lo, hi = dem.elevation_range()
    print(
        f"{root / 'dem.tif'}: {g.ncols}x{g.nrows} cells of {g.cell_m:g} m, "
        f"E {g.x_min:.1f} .. {g.x_max:.1f}, N {g.y_min:.1f} .. {g.y_max:.1f} m; "
        f"Z {lo:.2f} .. {hi:.2f} m (local frame)"
    )
    print(
        f"  frame anchor lat {frame.lat_deg:.7f} lon {frame.lon_deg:.7f} h {frame.h_m:.3f} m "
        f"(WGS84 ellipsoidal){'' if exists else ', new site'}"
    )
    n_anchor = float(geoid.undulation_m(frame.lat_deg, frame.lon_deg))
    datum = (
        f"orthometric, h = H + N with N from {geoid.description}, {n_anchor:.3f} m at the anchor"
        if args.vertical_datum == "orthometric"
        else f"ellipsoidal (WGS84); site vertical datum: {geoid.datum}"
    )
    print(f"  source heights: {datum}")
    print(f"  site bounds: {bounds_note}; resampling {args.resampling}, cell {g.cell_m:g} m")
    for info, cells in zip(infos, result.tile_cells, strict=True):
        unit = info.z_unit_m(z_unit)
        print(f"  {info.path}: {info.crs_name}, height unit {unit:.10g} m, {cells:,} cells")
    total = dem.elevation.size
    print(
        f"  {100 * (dem.count > 0).sum() / total:.1f} % of cells from tiles, "
        f"{result.filled_cells:,} filled from {args.coarse or 'no coarse DEM'}, "
        f"{result.hole_cells:,} holes"
    )
    return 0


# --------------------------------------------------------------------------- import-ortho


def _run_import_ortho(args: argparse.Namespace) -> int:
    from demtrack.core.site.folder import load_site
    from demtrack.core.site.ortho_import import import_orthophoto
    from demtrack.core.site.orthophoto import write_orthophoto
    from demtrack.core.site.update import read_manifest, write_atomic, write_manifest
    from demtrack.core.terrain.crs_import import local_crs_wkt
    from demtrack.core.terrain.dem_import import native_cell_m, read_raster_info
    from demtrack.core.terrain.grid import GridSpec

    root: Path = args.site
    site = load_site(root)
    doc = read_manifest(root)
    info = read_raster_info(args.image)
    dem_grid = site.dem.grid
    x0, y0, x1, y1 = dem_grid.bounds
    cell = args.cell or round(native_cell_m(info, site.frame), 3)
    cell = max(cell, max(x1 - x0, y1 - y0) / _MAX_ORTHO_SIDE)
    grid = GridSpec.covering(x0, y0, x1, y1, cell)
    result = import_orthophoto(args.image, site.frame, grid, site.dem)
    name = doc.get("orthophoto") or "ortho.tif"
    wkt = local_crs_wkt(site.frame)
    write_atomic(root / name, lambda p: write_orthophoto(p, result.rgb, grid, wkt))
    doc["orthophoto"] = name
    write_manifest(root, doc)
    print(
        f"{root / name}: {grid.ncols}x{grid.nrows} cells of {grid.cell_m:g} m from "
        f"{args.image} ({info.crs_name}); covers {100 * result.coverage:.1f} % of the site"
    )
    return 0


# --------------------------------------------------------------------------- import-roads


def _run_import_roads(args: argparse.Namespace) -> int:
    import numpy as np

    from demtrack.core.site.folder import load_site
    from demtrack.core.site.road_io import (
        read_road_lines,
        read_roads_geojson,
        road_lines_to_geojson,
    )
    from demtrack.core.site.update import read_manifest, write_atomic, write_manifest

    root: Path = args.site
    site = load_site(root)
    doc = read_manifest(root)
    lines = read_road_lines(args.roads, crs=args.crs, layer=args.layer)
    name = doc.get("roads") or "roads.geojson"
    text = json.dumps(road_lines_to_geojson(lines))
    tmp_check = root / f".{name}.check"
    try:
        tmp_check.write_text(text, encoding="utf-8")
        roads = read_roads_geojson(tmp_check, site.frame)  # the site will read it so
    finally:
        tmp_check.unlink(missing_ok=True)
    write_atomic(root / name, lambda p: p.write_text(text, encoding="utf-8"))
    doc["roads"] = name
    write_manifest(root, doc)
    x0, y0, x1, y1 = site.dem.grid.bounds
    xy = np.concatenate([np.asarray(line.coords) for line in roads.lines])
    inside = (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
    print(
        f"{root / name}: {len(roads)} road line(s) from {args.roads}; "
        f"{100 * inside.mean():.1f} % of their vertices lie on the DEM"
    )
    return 0


# --------------------------------------------------------------------------- add-camera


def _intrinsics(args: argparse.Namespace) -> Intrinsics:
    from demtrack.core.camera.pinhole import Intrinsics

    if args.intrinsics is not None:
        try:
            data = json.loads(Path(args.intrinsics).read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise CameraError(f"{args.intrinsics} is not valid JSON: {exc.msg}") from None
        if isinstance(data, dict) and "intrinsics" in data:
            data = data["intrinsics"]
        return Intrinsics.from_dict(data)
    if args.fx is None or args.width is None or args.height is None:
        raise CameraError("give --intrinsics FILE.json, or --fx, --width and --height")
    w, h = args.width, args.height
    return Intrinsics(
        args.fx,
        args.fy if args.fy is not None else args.fx,
        args.cx if args.cx is not None else (w - 1) / 2.0,
        args.cy if args.cy is not None else (h - 1) / 2.0,
        w,
        h,
        args.k1,
        args.k2,
        args.p1,
        args.p2,
        args.k3,
        args.k4,
    )


def _pose(args: argparse.Namespace, site: Site, intr: Intrinsics, crs: Any) -> SurveyedPose:
    """The surveyed pose from --az/--tilt/--roll, --opk or --rotation (exactly one)."""
    from demtrack.core.camera.pose import (
        pose_from_rotation,
        pose_from_survey,
        rotation_from_opk_deg,
    )

    given = [o for o, v in (("--az", args.az), ("--opk", args.opk), ("--rotation", args.rotation))
             if v is not None]  # fmt: skip
    if len(given) != 1:
        raise CameraError(
            "give the orientation once: --az with --tilt (and --roll), or --opk OMEGA PHI "
            f"KAPPA, or --rotation R11 .. R33 (got {', '.join(given) or 'none'})"
        )
    x, y, z = args.position
    # the geoid's N at the camera itself (per point for a grid such as EGM96)
    n_geoid = _n_at(site.geoid, x, y, crs) if args.vertical_datum == "orthometric" else 0.0
    if args.az is not None:
        if args.tilt is None:
            raise CameraError("--az needs --tilt (negative looks down)")
        return pose_from_survey(
            site.frame, intr, x, y, z, crs, args.az, args.tilt, args.roll or 0.0,
            north=args.north or "true", geoid_undulation_m=n_geoid,
        )  # fmt: skip
    if args.tilt is not None or args.roll is not None:
        raise CameraError(f"--tilt and --roll go with --az, not with {given[0]}")
    if args.opk is not None:
        rot = rotation_from_opk_deg(*args.opk)
    else:
        import numpy as np

        rot = np.asarray(args.rotation, dtype=float).reshape(3, 3)
    try:
        return pose_from_rotation(
            site.frame, intr, x, y, z, crs, rot, north=args.north, geoid_undulation_m=n_geoid
        )
    except CameraError as exc:
        raise CameraError(f"{given[0]}: {exc}") from None


def _run_add_camera(args: argparse.Namespace) -> int:
    from demtrack.core.camera.pantilt import PanTiltHead
    from demtrack.core.camera.pose import check_camera_on_dem
    from demtrack.core.geo.geodesy import as_crs
    from demtrack.core.site.folder import Sensor, load_site
    from demtrack.core.site.update import read_manifest, write_atomic, write_manifest

    root: Path = args.site
    site = load_site(root)
    doc = read_manifest(root)
    if args.id in site.sensors and not args.replace:
        raise SiteError(f"sensor {args.id!r} already exists; pass --replace to overwrite it")
    intr = _intrinsics(args)
    crs = as_crs(args.crs)
    if args.vertical_datum == "orthometric" and not site.geoid.orthometric:
        raise SiteError(
            "--vertical-datum orthometric: this site states no geoid (site.json vertical_datum)"
        )
    pose = _pose(args, site, intr, crs)
    check_camera_on_dem(args.id, pose.camera.position_enu, site.dem)
    image_rel = None
    if args.image is not None:
        src = Path(args.image)
        if not src.is_file():
            raise SiteError(f"image not found: {src}")
        image_rel = f"images/{args.id}{src.suffix.lower()}"
    head = PanTiltHead(pose.camera.position_enu, pose.site_az_deg - args.pan, intr)
    sensor = Sensor(
        args.id, args.name or args.id, head, args.pan, pose.site_tilt_deg, None, pose.site_roll_deg
    )
    entry = sensor.to_dict(root)
    if image_rel is not None:
        (root / "images").mkdir(exist_ok=True)
        write_atomic(root / image_rel, lambda p: shutil.copyfile(args.image, p))
        entry["image"] = image_rel
    sensors = [s for s in doc.get("sensors", []) if s.get("id") != args.id]
    sensors.append(entry)
    doc["sensors"] = sensors
    write_manifest(root, doc)
    e, n, u = pose.camera.position_enu
    print(
        f"{args.id}: at E {e:.3f} N {n:.3f} U {u:.3f} m (lat {pose.lat_deg:.8f} "
        f"lon {pose.lon_deg:.8f} h {pose.h_m:.3f} m ellipsoidal)"
    )
    if args.az is None:
        from demtrack.core.geo.geodesy import horizontal_crs

        grid = args.north == "grid" or (args.north is None and horizontal_crs(crs).is_projected)
        axes = "the CRS's grid axes" if grid else "east, true north, up at the camera"
        ref = (
            f"rotation in {axes} (convergence {pose.convergence_deg:+.4f} deg); "
            f"optical axis at true azimuth {pose.az_true_deg:.4f} deg"
        )
    elif args.north == "grid":
        ref = (
            f"grid azimuth {args.az:.4f} + convergence {pose.convergence_deg:+.4f} = true "
            f"{pose.az_true_deg:.4f} deg"
        )
    else:
        ref = f"true azimuth {pose.az_true_deg:.4f} deg"
    print(
        f"  {ref}; in the site frame az {pose.site_az_deg:.4f} tilt "
        f"{pose.site_tilt_deg:.4f} roll {pose.site_roll_deg:.4f} deg"
    )
    return 0


# --------------------------------------------------------------------------- parsers


def _site(p: argparse.ArgumentParser) -> None:
    p.add_argument("--site", type=Path, required=True, metavar="DIR", help="site folder")


def _datum(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--vertical-datum",
        required=True,
        choices=("ellipsoidal", "orthometric"),
        help=f"what the {what} heights are measured from: the WGS84 ellipsoid, or the "
        "site's geoid (h = H + N(lat, lon), N from its vertical datum)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``import-dem``, ``import-ortho``, ``import-roads`` and ``add-camera``."""
    p = sub.add_parser("import-dem", help="warp and mosaic GeoTIFF DEM tiles (any CRS) into a site")
    _site(p)
    p.add_argument("tiles", type=Path, nargs="+", metavar="TILE.tif", help="first listed wins")
    _datum(p, "tiles'")
    p.add_argument("--coarse", type=Path, metavar="FILE", help="coarse DEM filling the holes")
    p.add_argument(
        "--geoid", metavar="egm96|FILE|none",
        help="new site's vertical datum: EGM96 (PROJ's egm96_15.gtx, Debian's proj-data), a "
        "PROJ-readable geoid grid (.gtx/.tif, copied into the site), or none (ellipsoidal)",
    )  # fmt: skip
    p.add_argument(
        "--geoid-undulation", type=finite, metavar="N", help="new site: one constant N (m)"
    )
    p.add_argument("--z-unit", choices=tuple(_Z_UNITS), help="height unit (default: per file)")
    p.add_argument(
        "--cell",
        type=positive,
        metavar="M",
        help="cell size (default: native; a finer cell keeps more of the source's detail)",
    )
    p.add_argument(
        "--resampling",
        choices=_RESAMPLING,
        default="bilinear",
        help="how the tiles are sampled at the site's cells (default bilinear; average "
        "for a cell coarser than the tiles')",
    )
    p.add_argument(
        "--bounds",
        type=float,
        nargs=4,
        metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
        help="site-frame bounds (m); default the largest rectangle inside the tiles' "
        "warped footprint",
    )
    p.add_argument(
        "--anchor", type=float, nargs=3, metavar=("LAT", "LON", "H"), help="new site's anchor"
    )
    p.add_argument("--name", help="site name (new site)")
    p.add_argument(
        "--sigma", type=non_negative, default=0.0, metavar="M", help="tiles' 1-sigma (m)"
    )
    p.add_argument(
        "--coarse-sigma", type=positive, default=1.0, metavar="M", help="coarse DEM 1-sigma"
    )
    p.set_defaults(func=_run_import_dem)

    p = sub.add_parser("import-ortho", help="resample an RGB GeoTIFF (any CRS) onto the site")
    _site(p)
    p.add_argument("image", type=Path, metavar="ORTHO.tif")
    p.add_argument("--cell", type=positive, metavar="M", help="cell size (default: native)")
    p.set_defaults(func=_run_import_ortho)

    p = sub.add_parser("import-roads", help="road lines from GeoJSON or GeoPackage (any CRS)")
    _site(p)
    p.add_argument("roads", type=Path, metavar="ROADS.geojson|.gpkg")
    p.add_argument("--crs", help="CRS of the coordinates (default: the file's)")
    p.add_argument("--layer", help="GeoPackage layer")
    p.set_defaults(func=_run_import_roads)

    p = sub.add_parser("add-camera", help="add a camera surveyed in WGS84 or a projected CRS")
    _site(p)
    p.add_argument("--id", required=True)
    p.add_argument("--name")
    p.add_argument(
        "--position", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"),
        help="optical centre: easting northing height, or lon lat height",
    )  # fmt: skip
    p.add_argument("--crs", default="EPSG:4979", help="CRS of --position (default EPSG:4979)")
    _datum(p, "camera's")
    p.add_argument("--az", type=float, metavar="DEG", help="azimuth, clockwise (with --tilt)")
    p.add_argument(
        "--north", choices=("true", "grid"),
        help="--az is from true north (default) or from the CRS's grid north; --opk and "
        "--rotation are in the CRS's grid axes (default for a projected CRS) or true ENU",
    )  # fmt: skip
    p.add_argument("--tilt", type=float, metavar="DEG", help="negative = down")
    p.add_argument("--roll", type=float, metavar="DEG", help="with --az (default 0)")
    p.add_argument(
        "--opk", type=float, nargs=3, metavar=("OMEGA", "PHI", "KAPPA"),
        help="photogrammetric omega phi kappa (deg; R = Rx Ry Rz, camera x right y up z back)",
    )  # fmt: skip
    p.add_argument(
        "--rotation", type=float, nargs=9, metavar="R",
        help="R_world_cam row by row: OpenCV camera axes (x right, y down, z forward) "
        "into the world axes (see --north)",
    )  # fmt: skip
    p.add_argument("--pan", type=float, default=0.0, metavar="DEG", help="head pan reading")
    p.add_argument("--intrinsics", metavar="FILE.json")
    for key in ("fx", "fy"):
        p.add_argument(f"--{key}", type=positive, metavar="PX")
    for key in ("cx", "cy"):
        p.add_argument(f"--{key}", type=float, metavar="PX")
    p.add_argument("--width", type=positive_int, metavar="PX")
    p.add_argument("--height", type=positive_int, metavar="PX")
    for key in ("k1", "k2", "p1", "p2", "k3"):
        p.add_argument(f"--{key}", type=float, default=0.0)
    p.add_argument("--k4", type=float, default=0.0, help="r^8 term (not OpenCV's rational k4)")
    p.add_argument("--image", metavar="FILE", help="a still from the camera")
    p.add_argument("--replace", action="store_true", help="overwrite a sensor of that id")
    p.set_defaults(func=_run_add_camera)
