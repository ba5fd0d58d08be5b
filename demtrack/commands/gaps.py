"""``demtrack gaps``: track detections and say why each track has its gaps."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .choices import DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument, positive

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.geolocation.fix_builder import build_fixes, sensor_sizes
    from demtrack.core.io.detections import read_detections
    from demtrack.core.site.folder import load_site
    from demtrack.core.tracking import run_tracker
    from demtrack.core.visibility.gap_explain import explain_track_gaps

    site = load_site(args.site)
    # With --json stdout holds only the JSON document; the read summaries go to stderr.
    log = sys.stderr if args.json else sys.stdout
    detections, ingest = read_detections(args.detections, sensors=sensor_sizes(site))
    print(ingest.summary(), file=log)
    if ingest.time_note:
        print(ingest.time_note, file=log)
    fixes, report = build_fixes(site, detections)
    print(report.summary(), file=log)
    tracks = run_tracker(fixes, args.method, roads=site.roads)
    cameras = {sid: sensor.camera for sid, sensor in site.sensors.items()}
    explained = [
        (track, explain_track_gaps(site.dem, cameras, track, max_range_m=args.max_range))
        for track in tracks
    ]
    if args.json:
        doc = [
            {
                "track_id": track.id,
                "class": track.cls,
                "t_start_s": float(track.t_s[0]),
                "t_end_s": float(track.t_s[-1]),
                "gaps": [g.to_dict() for g in gaps],
            }
            for track, gaps in explained
        ]
        print(json.dumps(doc, indent=2))
        return 0
    n_gaps = sum(len(g) for _, g in explained)
    print(f"{args.method}: {len(tracks)} track(s), {n_gaps} gap(s)")
    for track, gaps in explained:
        print(
            f"track {track.id} ({track.cls}) {track.t_s[0]:.1f}-{track.t_s[-1]:.1f} s:"
            f" {len(gaps)} gap(s)"
        )
        for g in gaps:
            line = f"  {g.t_start_s:7.1f}-{g.t_end_s:7.1f} s  {g.reason}"
            blockers = g.to_dict()["blockers"]
            if g.reason == "occluded" and blockers:
                b = blockers[0]
                e, n, u = b["p_enu"]
                line += (
                    f" by {b['kind']} ({b['above_ground_m']:.1f} m above ground) from"
                    f" {b['sensor']} at E {e:.1f} N {n:.1f} U {u:.1f}"
                )
            print(line)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``gaps`` command."""
    p = sub.add_parser("gaps", help="track detections and explain why each track has gaps")
    add_site_argument(p)
    p.add_argument(
        "--detections",
        required=True,
        type=Path,
        metavar="FILE",
        help="detections (.csv or .jsonl; see docs/trajectories.md)",
    )
    p.add_argument(
        "--method",
        choices=list(TRACKING_METHODS),
        default=DEFAULT_METHOD,
        help=f"tracking method (default {DEFAULT_METHOD})",
    )
    p.add_argument(
        "--max-range",
        type=positive,
        default=1000.0,
        metavar="M",
        help="cameras see no further than this (default 1000 m)",
    )
    p.add_argument("--json", action="store_true", help="print the explanations as JSON")
    p.set_defaults(func=_run)
