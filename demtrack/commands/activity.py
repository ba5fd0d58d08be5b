"""``demtrack activity``: loitering, rendezvous, convoys and zone crossings from detections."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .choices import DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument, positive

__all__ = ["register"]


def _given(**values: float | None) -> dict[str, Any]:
    """The options the user set; the rest keep the detector parameters' own defaults."""
    return {k: v for k, v in values.items() if v is not None}


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.activity.convoy import ConvoyParams, detect_convoys
    from demtrack.core.activity.loitering import LoiterParams, detect_loitering
    from demtrack.core.activity.rendezvous import RendezvousParams, detect_rendezvous
    from demtrack.core.activity.zones import detect_zone_crossings
    from demtrack.core.site.folder import load_site
    from demtrack.core.site.zone_io import read_zones_geojson

    from .track import track_detections

    site = load_site(args.site)
    zones = read_zones_geojson(args.zones, site.frame) if args.zones else []
    tracks = track_detections(site, args.detections, args.method)
    loiter = LoiterParams(**_given(radius_m=args.loiter_radius, min_duration_s=args.loiter_time))
    meet = RendezvousParams(**_given(distance_m=args.meet_distance, min_duration_s=args.meet_time))
    convoy = ConvoyParams(**_given(min_distance_m=args.convoy_distance))
    events = (
        detect_loitering(tracks, loiter)
        + detect_rendezvous(tracks, meet)
        + detect_convoys(tracks, convoy)
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
    p.add_argument("--method", choices=list(TRACKING_METHODS), default=DEFAULT_METHOD)
    p.add_argument("--zones", type=Path, metavar="ZONES.geojson", help="polygons (lon/lat)")
    # Unset options (None) keep LoiterParams / RendezvousParams / ConvoyParams defaults.
    p.add_argument("--loiter-radius", type=positive, metavar="M")
    p.add_argument("--loiter-time", type=positive, metavar="S")
    p.add_argument("--meet-distance", type=positive, metavar="M")
    p.add_argument("--meet-time", type=positive, metavar="S")
    p.add_argument("--convoy-distance", type=positive, metavar="M")
    p.add_argument("--json", action="store_true", help="print events as JSON")
    p.set_defaults(func=_run)
