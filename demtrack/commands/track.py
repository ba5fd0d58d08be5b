"""``demtrack track``: detections -> fixes -> tracks (GeoJSON, CSV, GPX, KML, KMZ, GPKG).

The files are written by :mod:`demtrack.core.io.track_io`, the writers the server's
``/api/tracks/export`` uses: same heights (the site's geoid model, else ellipsoidal and
said so) and times (real UTC from UNIX seconds; ``--epoch`` + t_s for session seconds,
declared in the file).

``--poses FILE`` (repeatable; each file may hold several sensors) reads pose telemetry
(:mod:`demtrack.core.io.pose_io`): those sensors' detections are geolocated at the pose
of their moment, and any without a pose close enough are counted ``no_pose``. Inline
poses in the detection file (``pan_deg``/``tilt_deg``/``hfov_deg``) are used for sensors
no pose file covers. ``--estimate-latency SENSOR`` estimates that sensor's telemetry
latency from its track's jitter (:mod:`demtrack.core.geolocation.pose_latency`), prints
it and uses it.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING

from demtrack.core.errors import InputFileError

from .choices import DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument

if TYPE_CHECKING:
    from demtrack.core.camera.pose_series import PoseSeries
    from demtrack.core.site.folder import Site
    from demtrack.core.tracking import Track

__all__ = ["DEFAULT_METHOD", "check_track_suffix", "register", "track_detections"]

UNIX_EPOCH_DT = datetime(1970, 1, 1, tzinfo=UTC)
SUFFIXES = (".geojson", ".json", ".csv", ".gpx", ".kml", ".kmz", ".gpkg")


def _epoch(text: str | None) -> datetime | None:
    if text is None:
        return None
    from demtrack.core.io.times import parse_iso_time

    return UNIX_EPOCH_DT + timedelta(seconds=parse_iso_time(text, "--epoch"))


def read_pose_files(site: Site, paths: Sequence[Path]) -> dict[str, PoseSeries]:
    """Pose series of every file, by sensor; prints each file's report."""
    from demtrack.core.io.pose_io import read_poses

    poses: dict[str, PoseSeries] = {}
    for path in paths:
        got, report = read_poses(path, sensors=set(site.sensors))
        print(f"{path}: {report.summary()}")
        if report.time_note:
            print(report.time_note)
        for sid, series in got.items():
            if sid in poses:
                raise InputFileError(f"sensor {sid!r} has poses in two --poses files: keep one")
            poses[sid] = series
    return poses


def track_detections(
    site: Site,
    detections_path: Path,
    method: str,
    poses_paths: Sequence[Path] = (),
    estimate_latency: str | None = None,
) -> list[Track]:
    """Read detections (and poses), geolocate them into fixes and track; prints the counts."""
    from demtrack.core.geolocation.fix_builder import build_fixes, sensor_sizes
    from demtrack.core.io.detections import read_detections
    from demtrack.core.io.pose_io import poses_from_detections
    from demtrack.core.tracking import run_tracker

    detections, ingest = read_detections(detections_path, sensors=sensor_sizes(site))
    print(ingest.summary())
    if ingest.time_note:
        print(ingest.time_note)
    poses = {**poses_from_detections(ingest), **read_pose_files(site, poses_paths)}
    if estimate_latency is not None:
        site = _with_estimated_latency(site, detections, poses, estimate_latency)
    fixes, report = build_fixes(site, detections, poses=poses or None)
    print(report.summary())
    return run_tracker(fixes, method, roads=site.roads)


def _with_estimated_latency(
    site: Site, detections: list, poses: dict[str, PoseSeries], sensor_id: str
) -> Site:
    """The site with ``sensor_id``'s pose latency estimated from the data (printed)."""
    from demtrack.core.geolocation.pose_latency import estimate_pose_latency

    sensor = site.sensor(sensor_id)
    if sensor_id not in poses:
        raise InputFileError(f"--estimate-latency {sensor_id}: no poses for that sensor")
    est = estimate_pose_latency(site, detections, poses[sensor_id], sensor_id)
    print(f"{sensor_id}: {est.summary()}")
    sensors = {**site.sensors, sensor_id: replace(sensor, pose_latency_s=est.latency_s)}
    return replace(site, sensors=sensors)


def check_track_suffix(out: Path) -> str:
    """The track file's lower-case suffix; an unknown one is an :class:`InputFileError`."""
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputFileError(f"unknown track file type {suffix!r} (use {', '.join(SUFFIXES)})")
    return suffix


def _run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    check_track_suffix(out)
    epoch = _epoch(args.epoch)
    from demtrack.core.site.folder import load_site

    site = load_site(args.site)
    tracks = track_detections(site, args.detections, args.method, args.poses, args.estimate_latency)
    from demtrack.server.track_export import write_track_file

    write_track_file(site, tracks, out, epoch)
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
        "--poses",
        action="append",
        default=[],
        metavar="FILE",
        help="pose telemetry (.csv or .jsonl; repeatable, a file may hold several sensors;"
        " see docs/site-format.md): those sensors' detections are geolocated at the pose"
        " of their moment, or counted no_pose",
    )
    p.add_argument(
        "--estimate-latency",
        metavar="SENSOR",
        help="estimate SENSOR's telemetry latency from its track's jitter, print and use it",
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
