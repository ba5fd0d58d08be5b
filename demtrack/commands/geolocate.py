"""``demtrack geolocate``: pixel -> every ground hit along its viewing ray."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from .choices import GEOLOCATE_RULES
from .common import add_site_argument, any_number, positive

if TYPE_CHECKING:
    from demtrack.core.geolocation.geolocate import Geolocation, GroundHit
    from demtrack.core.terrain.dem import Dem

__all__ = ["print_geolocation", "register"]


def _hit_line(tag: str, h: GroundHit) -> str:
    from demtrack.core.geo.grid_ref import grid_refs

    e, n, u = h.p_enu
    return (
        f"  {tag:<8} E {e:9.3f}  N {n:9.3f}  U {u:7.3f} m | lat {h.lat_deg:.8f}"
        f"  lon {h.lon_deg:.8f}  h {h.h_m:8.3f} m | range {h.range_m:7.2f} m"
        f" | sigma {h.sigma_m:5.2f} m | MGRS {grid_refs(h.lat_deg, h.lon_deg)['mgrs'] or '-'}"
    )


def hole_note(g: Geolocation, dem: Dem | None) -> str:
    """The DEM-hole warning: where the first hole under the ray is, when the DEM is given."""
    if not g.crossed_nodata:
        return ""
    from demtrack.core.geolocation.hole_crossing import first_hole_crossing

    hole = first_hole_crossing(dem, g.origin_enu, g.direction_enu) if dem is not None else None
    where = f" {hole.describe()}" if hole is not None else ""
    return f" (the ray crossed a DEM hole{where}; a crossing may be missing)"


def print_geolocation(g: Geolocation, dem: Dem | None = None) -> None:
    """Human-readable answer: the selected hits, then every hit and the road point.

    With ``dem`` (the site's), the DEM-hole warning says where the hole is.
    """
    note = hole_note(g, dem)
    print(f"  status {g.status}, {len(g.hits)} terrain hit(s), rule {g.rule!r}{note}")
    chosen = {id(h) for h in g.selected}
    for k, h in enumerate(g.hits):
        tag = f"hit {k + 1}" + ("*" if id(h) in chosen else "")
        print(_hit_line(tag, h))
    if g.road is not None:
        print(_hit_line("road*" if g.rule == "road" else "road", g.road))
    if not g.selected:
        print("  no point selected by this rule")


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.geolocation.geolocation_json import geolocation_to_dict
    from demtrack.core.site.folder import load_site

    site = load_site(args.site)
    sensor = site.sensor(args.sensor)
    geo = site.geolocator(pixel_sigma_px=args.pixel_sigma)
    g = geo.geolocate(sensor.camera, [args.pixel[0]], [args.pixel[1]], rule=args.rule)[0]
    if args.json:
        print(json.dumps(geolocation_to_dict(sensor.id, g), indent=2))
    else:
        print(f"{sensor.id} ({sensor.name}) pixel ({g.u:g}, {g.v:g}); * = selected")
        print_geolocation(g, site.dem)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``geolocate`` command."""
    p = sub.add_parser("geolocate", help="geolocate an image point on the terrain")
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID", help="sensor id from site.json")
    p.add_argument(
        "--pixel",
        required=True,
        nargs=2,
        type=any_number,  # the command says a NaN or far pixel is outside the image
        metavar=("U", "V"),
        help="column and row; (0, 0) is the centre of the top-left pixel",
    )
    p.add_argument("--rule", choices=GEOLOCATE_RULES, default="all", help="which hit(s) to report")
    p.add_argument(
        "--pixel-sigma",
        type=positive,
        default=1.0,
        metavar="PX",
        help="1-sigma pixel error for the uncertainty (default 1)",
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_run)
