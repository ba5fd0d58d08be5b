"""``demtrack sample-site`` and ``demtrack demo``."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from demtrack.core.geolocate import Geolocator
from demtrack.core.site import MANIFEST, Sensor, Site, load_site

from .common import DEFAULT_SITE
from .geolocate import print_geolocation

__all__ = ["ensure_sample_site", "register"]


def ensure_sample_site(path: Path, *, rebuild: bool = False) -> Path:
    """Build the sample site at ``path`` unless a site is already there."""
    from demtrack.samplesite.build import build_sample_site

    if rebuild and (path / MANIFEST).exists():
        shutil.rmtree(path)
    if not (path / MANIFEST).exists():
        print(f"building the sample site in {path} ...")
        build_sample_site(path, log=print)
    return path


def _sample_site(args: argparse.Namespace) -> int:
    ensure_sample_site(args.dir, rebuild=args.force)
    print(f"sample site ready: {args.dir}")
    return 0


def _showcase_pixel(site: Site, sensor: Sensor, geo: Geolocator) -> tuple[float, float, str]:
    """A pixel whose ray meets the terrain several times and ends on a road, if any.

    That is the paper's case: a tree crown in front of the road takes the first hit.
    """
    intr = sensor.camera.intrinsics
    v, u = np.mgrid[8 : intr.height : 16, 8 : intr.width : 16]
    results = geo.geolocate(sensor.camera, u.ravel().astype(float), v.ravel().astype(float))
    if site.roads is not None:
        for g in results:
            if len(g.hits) < 2:
                continue
            first, last = g.hits[0].p_enu, g.hits[-1].p_enu
            var = site.dem.sample_variance(
                np.array([first[0], last[0]]), np.array([first[1], last[1]])
            )
            # Laser returns spread through a crown (high variance); a road is smooth.
            on_road = site.roads.distance_m(last[:1], last[1:2])[0] < 3.0
            if on_road and var[0] > 1.0 and var[1] < 0.05:
                return g.u, g.v, "(a crown in front of the road)"
    return (intr.width - 1) / 2, intr.height * 0.8, "(open ground)"


def _demo(args: argparse.Namespace) -> int:
    site = load_site(ensure_sample_site(args.site))
    print(
        f"\nsite {site.name!r}: frame anchored at {site.frame.lat_deg:.6f}, "
        f"{site.frame.lon_deg:.6f}, h {site.frame.h_m:.1f} m (WGS84)"
    )
    lo, hi = site.dem.elevation_range()
    g = site.dem.grid
    print(
        f"DEM {g.ncols}x{g.nrows} cells of {g.cell_m} m, elevation {lo:.1f}..{hi:.1f} m; "
        f"{len(site.sensors)} sensors: {', '.join(site.sensors)}"
    )
    geo = site.geolocator()
    for sensor in site.sensors.values():
        u, v, why = _showcase_pixel(site, sensor, geo)
        print(
            f"\n{sensor.id} ({sensor.name}), pixel ({u:g}, {v:g}) {why}; every hit along the ray:"
        )
        print_geolocation(geo.geolocate(sensor.camera, [u], [v], rule="all")[0])
    print("\nnext: demtrack geolocate --sensor cam1 --pixel U V --rule all")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sample-site`` and ``demo`` commands."""
    p = sub.add_parser("sample-site", help="generate the synthetic Bushy Run sample site")
    p.add_argument("dir", type=Path, nargs="?", default=DEFAULT_SITE, help="output folder")
    p.add_argument("--force", action="store_true", help="rebuild even if the site exists")
    p.set_defaults(func=_sample_site)
    p = sub.add_parser("demo", help="build the sample site if needed and walk through it")
    p.add_argument("--site", type=Path, default=DEFAULT_SITE, metavar="DIR")
    p.set_defaults(func=_demo)
