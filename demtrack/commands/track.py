"""``demtrack track``: detections -> fixes -> tracks (GeoJSON, CSV, GPX, KML, KMZ, GPKG).

The files are written by :mod:`demtrack.core.io.track_io`, the writers the server's
``/api/tracks/export`` uses: same heights (the site's geoid model, else ellipsoidal and
said so) and times (real UTC from UNIX seconds; ``--epoch`` + t_s for session seconds,
declared in the file).
"""

from __future__ import annotations

import argparse
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING

from demtrack.core.errors import InputFileError

from .choices import DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument

if TYPE_CHECKING:
    from demtrack.core.site.folder import Site
    from demtrack.core.tracking import Track

__all__ = ["DEFAULT_METHOD", "register", "track_detections"]

UNIX_EPOCH_DT = datetime(1970, 1, 1, tzinfo=UTC)
SUFFIXES = (".geojson", ".json", ".csv", ".gpx", ".kml", ".kmz", ".gpkg")


def _epoch(text: str | None) -> datetime | None:
    if text is None:
        return None
    from demtrack.core.io.times import parse_iso_time

    return UNIX_EPOCH_DT + timedelta(seconds=parse_iso_time(text, "--epoch"))


def track_detections(site: Site, detections_path: Path, method: str) -> list[Track]:
    """Read detections, geolocate them into fixes and track; prints what was skipped."""
    from demtrack.core.geolocation.fix_builder import build_fixes, sensor_sizes
    from demtrack.core.io.detections import read_detections
    from demtrack.core.tracking import run_tracker

    detections, ingest = read_detections(detections_path, sensors=sensor_sizes(site))
    print(ingest.summary())
    if ingest.time_note:
        print(ingest.time_note)
    fixes, report = build_fixes(site, detections)
    print(report.summary())
    return run_tracker(fixes, method, roads=site.roads)


def _run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputFileError(f"unknown track file type {suffix!r} (use {', '.join(SUFFIXES)})")
    epoch = _epoch(args.epoch)
    from demtrack.core.io.track_io import TRACK_CSVT, TimeBase, write_tracks
    from demtrack.core.site.folder import load_site
    from demtrack.server.track_export import site_heights

    site = load_site(args.site)
    tracks = track_detections(site, args.detections, args.method)
    frame = site.frame

    def to_geodetic(e: float, n: float, u: float) -> tuple[float, float, float]:
        lat, lon, h = frame.to_geodetic(e, n, u)
        return float(lat), float(lon), float(h)

    fmt = "geojson" if suffix == ".json" else suffix[1:]
    # Real UTC when the times are UNIX seconds; session seconds (a declared --epoch, or
    # all before 2000) are said to be relative in the file.
    times = TimeBase.for_times([p.t_s for t in tracks for p in t.points], epoch)
    heights = site_heights(site)  # the server's rule: EGM96, else the site's N, else none
    write_tracks(fmt, out, tracks, to_geodetic, times=times, heights=heights)
    if fmt == "csv":
        # GDAL's column types for the CSV, beside it (ogr reads x.csvt with x.csv).
        out.with_suffix(".csvt").write_text(TRACK_CSVT, encoding="utf-8")
    n_gaps = sum(len(t.gaps) for t in tracks)
    print(f"{args.method}: {len(tracks)} track(s), {n_gaps} gap(s) -> {out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``track`` command."""
    p = sub.add_parser("track", help="track objects from a detections file")
    add_site_argument(p)
    p.add_argument(
        "--detections",
        required=True,
        metavar="FILE",
        help="detections (.csv or .jsonl; see docs/trajectories.md)",
    )
    p.add_argument(
        "--method",
        choices=list(TRACKING_METHODS),
        default=DEFAULT_METHOD,
        help="tracking method (default multi-hypothesis-road)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="tracks file: .geojson, .csv (with a .csvt), .gpx, .kml, .kmz or .gpkg",
    )
    p.add_argument(
        "--epoch",
        metavar="ISO8601",
        help="for detections in session seconds: ISO 8601 time (with a zone) of t = 0 s,"
        " declared in the file (default none: times are UNIX seconds, real UTC)",
    )
    p.set_defaults(func=_run)
