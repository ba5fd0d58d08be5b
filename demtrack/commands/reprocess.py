"""``demtrack reprocess``: an archive of detections -> fixes and tracks, in parallel.

See :mod:`demtrack.reprocess` and docs/reprocess.md. ``--engine local`` (the default)
runs in this process; ``--engine dask`` on a new ``LocalCluster`` of ``--workers``
processes, or on the cluster of ``--scheduler``. Both write the same outputs, and the
same content hash, printed at the end.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .choices import DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument, positive, positive_int

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.reprocess.run import ReprocessSettings, reprocess
    from demtrack.reprocess.tasks import site_at
    from demtrack.server.track_export import write_track_file

    from .track import check_track_suffix

    tracks_name = f"tracks{args.tracks_format}"
    check_track_suffix(Path(tracks_name))
    settings = ReprocessSettings(
        method=args.method,
        engine=args.engine,
        workers=args.workers,
        scheduler=args.scheduler,
        window_s=args.window_s,
        chunk_s=args.chunk_s,
        quiet_s=args.quiet_s,
        progress=True,
        say=print,
    )
    site = site_at(str(args.site))
    manifest = reprocess(
        str(args.site),
        args.archive,
        Path(args.output),
        settings,
        tracks_name=tracks_name,
        write_tracks=lambda tracks, path: write_track_file(site, tracks, path, batch_geodetic=True),
    )
    run = manifest["run"]
    skipped = {**manifest["archive_skipped"], **manifest["geolocation_skipped"]}
    print(
        f"{manifest['n_detections']} detection(s) of {manifest['n_records']} record(s) ->"
        f" {manifest['n_fixes']} fix(es), {manifest['n_tracks']} track(s);"
        f" {len(manifest['groups'])} sensor group(s), {manifest['n_segments']} segment(s),"
        f" {manifest['n_parts']} geolocation part(s)"
        + (
            f"; skipped: {', '.join(f'{k} {v}' for k, v in sorted(skipped.items()))}"
            if skipped
            else ""
        )
    )
    n = manifest["n_detections"]
    rate = n / run["run_s"] if run["run_s"] > 0 else float("inf")
    print(
        f"{run['engine']}: planned in {run['plan_s']:.1f} s, ran in {run['run_s']:.1f} s"
        f" ({rate:.0f} detections/s) -> {args.output}"
    )
    print(f"content hash: sha256:{manifest['content_hash']}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``reprocess`` command."""
    p = sub.add_parser("reprocess", help="geolocate and track a detection archive in parallel")
    add_site_argument(p)
    p.add_argument(
        "--archive",
        required=True,
        metavar="SRC",
        help="detections: .jsonl, .csv, .parquet file or archive folder, a store's .sqlite3"
        " file or a database URL",
    )
    p.add_argument(
        "--method",
        choices=list(TRACKING_METHODS),
        default=DEFAULT_METHOD,
        help=f"tracking method (default {DEFAULT_METHOD})",
    )
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    p.add_argument("--engine", choices=("local", "dask"), default="local", help="default local")
    p.add_argument(
        "--workers", type=positive_int, default=2, metavar="N", help="Dask workers (default 2)"
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://HOST:PORT) instead of a new LocalCluster",
    )
    p.add_argument(
        "--tracks-format",
        choices=(".geojson", ".csv", ".gpx", ".kml", ".kmz", ".gpkg"),
        default=".geojson",
        help="the tracks file's format (default .geojson)",
    )
    p.add_argument(
        "--window-s",
        type=positive,
        default=3600.0,
        metavar="S",
        help="tracking window (s): state handed on exactly, changes nothing but task size",
    )
    p.add_argument(
        "--chunk-s",
        type=positive,
        default=600.0,
        metavar="S",
        help="geolocation part: one sensor's detections of this many seconds",
    )
    p.add_argument(
        "--quiet-s",
        type=positive,
        default=60.0,
        metavar="S",
        help="a group silent this long starts a new, independently tracked segment",
    )
    p.set_defaults(func=_run)
