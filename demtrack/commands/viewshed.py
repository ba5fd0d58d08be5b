"""``demtrack viewshed``: what each camera sees, coverage and blind spots."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from demtrack.core.visibility.target_heights import DEFAULT_TARGET_HEIGHT_M

from .common import (
    add_site_argument,
    non_negative,
    non_negative_int,
    positive,
    require_suffix,
)

if TYPE_CHECKING:
    import numpy as np

__all__ = ["register", "write_coverage"]


def write_coverage(path: Path, count: np.ndarray, masks: dict[str, np.ndarray], dem) -> None:
    """GeoTIFF on the DEM grid: band 1 the number of sensors, then one 0/1 band per sensor."""
    import numpy as np
    import rasterio

    g = dem.grid
    profile = {
        "driver": "GTiff",
        "height": g.nrows,
        "width": g.ncols,
        "count": 1 + len(masks),
        "dtype": "uint8",
        "transform": g.transform,
        "compress": "deflate",
    }
    if dem.crs_wkt:
        profile["crs"] = dem.crs_wkt
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(count.astype(np.uint8), 1)
        dst.set_band_description(1, "sensors_seeing")
        for k, (sid, mask) in enumerate(masks.items(), start=2):
            dst.write(mask.astype(np.uint8), k)
            dst.set_band_description(k, f"seen_by_{sid}")


#: DEMs with at least this many cells show a progress line on stderr.
_PROGRESS_CELLS = 1_000_000


def _progress(sensor_id: str):
    def show(share: float) -> None:
        end = "\n" if share >= 1.0 else ""
        print(f"\rviewshed {sensor_id}: {100 * share:3.0f} %", end=end, file=sys.stderr)

    return show


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from demtrack.core.site.folder import load_site
    from demtrack.core.visibility.viewshed import blind_spots, viewshed

    if args.output is not None:
        require_suffix(args.output, (".tif", ".tiff"), "--output")
    site = load_site(args.site)
    ids = args.sensor or list(site.sensors)
    sensors = [site.sensor(s) for s in ids]
    cell_area = site.dem.grid.cell_m**2
    data_area = float((~site.dem.nodata).sum()) * cell_area
    masks = {}
    t0 = time.perf_counter()
    for s in sensors:
        masks[s.id] = viewshed(
            site.dem,
            s.camera,
            mode=args.mode,
            target_height_m=args.target_height,
            max_range_m=args.max_range,
            mount_yaw_deg=s.head.mount_yaw_deg,
            curvature=args.curvature,
            method=args.method,
            progress=_progress(s.id) if site.dem.elevation.size >= _PROGRESS_CELLS else None,
        )
        area = masks[s.id].sum() * cell_area
        print(
            f"{s.id} ({s.name}): sees {area:,.0f} m2 ({100 * area / data_area:.1f} % of the site)"
        )
    count = np.sum(list(masks.values()), axis=0)
    print(
        f"seen by >= 1 sensor: {100 * (count >= 1).sum() * cell_area / data_area:.1f} %, "
        f">= 2: {100 * (count >= 2).sum() * cell_area / data_area:.1f} % "
        f"(mode {args.mode}, target {args.target_height:g} m above the surface, "
        f"{time.perf_counter() - t0:.2f} s)"
    )
    spots = blind_spots(count, site.dem, min_area_m2=args.min_area)
    print(f"blind spots of at least {args.min_area:g} m2: {len(spots)}")
    for b in spots[: args.blind_spots]:
        print(f"  {b.area_m2:9,.0f} m2 around E {b.centroid_e_m:7.1f} N {b.centroid_n_m:7.1f}")
    if args.output:
        write_coverage(args.output, count, masks, site.dem)
        print(f"coverage raster: {args.output}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``viewshed`` command."""
    p = sub.add_parser("viewshed", help="per-sensor viewsheds, coverage and blind spots")
    add_site_argument(p)
    p.add_argument("--sensor", action="append", metavar="ID", help="repeat; default all")
    p.add_argument(
        "--mode",
        choices=("fov", "reachable"),
        default="fov",
        help="current field of view, or anywhere the pan-tilt head can point",
    )
    p.add_argument(
        "--target-height",
        type=non_negative,
        default=DEFAULT_TARGET_HEIGHT_M,
        metavar="M",
        help=(
            f"target point above the surface (default {DEFAULT_TARGET_HEIGHT_M:g} m, a person;"
            " a car is 1.5 m)"
        ),
    )
    p.add_argument("--max-range", type=positive, default=1000.0, metavar="M")
    p.add_argument(
        "--method",
        choices=("sweep", "exact"),
        default="sweep",
        help="horizon sweep with exact re-checks (default) or one exact sight line per cell",
    )
    p.add_argument("--curvature", action="store_true", help="earth curvature and refraction")
    p.add_argument(
        "--min-area",
        type=non_negative,
        default=25.0,
        metavar="M2",
        help="smallest blind spot listed (default 25 m2)",
    )
    p.add_argument(
        "--blind-spots", type=non_negative_int, default=5, metavar="N", help="how many to print"
    )
    p.add_argument("-o", "--output", type=Path, metavar="COVERAGE.tif")
    p.set_defaults(func=_run)
