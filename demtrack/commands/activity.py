"""``demtrack activity``: loitering, rendezvous, convoys and zone crossings from detections."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from demtrack.core.activity import (
    ConvoyParams,
    LoiterParams,
    RendezvousParams,
    detect_convoys,
    detect_loitering,
    detect_rendezvous,
    detect_zone_crossings,
)
from demtrack.core.site import load_site
from demtrack.core.tracking import METHODS
from demtrack.core.zone_io import read_zones_geojson

from .common import add_site_argument
from .track import track_detections

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    site = load_site(args.site)
    zones = read_zones_geojson(args.zones, site.frame) if args.zones else []
    tracks = track_detections(site, args.detections, args.method)
    events = (
        detect_loitering(tracks, LoiterParams(args.loiter_radius, args.loiter_time))
        + detect_rendezvous(tracks, RendezvousParams(args.meet_distance, 0.5, args.meet_time))
        + detect_convoys(tracks, ConvoyParams(min_distance_m=args.convoy_distance))
        + detect_zone_crossings(tracks, zones)
    )
    events.sort(key=lambda e: (e.t_start_s, e.kind))
    if args.json:
        print(json.dumps([e.to_dict() for e in events], indent=2))
        return 0
    print(f"{len(tracks)} track(s), {len(events)} event(s)")
    for e in events:
        ids = ", ".join(str(i) for i in e.track_ids)
        what = e.details.get("zone", "")
        print(
            f"  {e.t_start_s:8.1f}-{e.t_end_s:8.1f} s  {e.kind:<11} tracks {ids:<10} "
            f"at E {e.p_enu[0]:7.1f} N {e.p_enu[1]:7.1f} {what}"
        )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``activity`` command."""
    p = sub.add_parser("activity", help="detect loitering, rendezvous, convoys, zone crossings")
    add_site_argument(p)
    p.add_argument("--detections", required=True, type=Path, metavar="FILE")
    p.add_argument("--method", choices=list(METHODS), default="multi-hypothesis-road")
    p.add_argument("--zones", type=Path, metavar="ZONES.geojson", help="polygons (lon/lat)")
    p.add_argument("--loiter-radius", type=float, default=10.0, metavar="M")
    p.add_argument("--loiter-time", type=float, default=60.0, metavar="S")
    p.add_argument("--meet-distance", type=float, default=5.0, metavar="M")
    p.add_argument("--meet-time", type=float, default=20.0, metavar="S")
    p.add_argument("--convoy-distance", type=float, default=100.0, metavar="M")
    p.add_argument("--json", action="store_true", help="print events as JSON")
    p.set_defaults(func=_run)
