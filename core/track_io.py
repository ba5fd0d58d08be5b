"""Track files: GeoJSON, CSV and GPX 1.1 writers.

Geodetic output needs a converter ``to_geodetic(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``
from the local frame (the site's :class:`~demtrack.core.geodesy.LocalFrame` provides one);
``h_m`` is the height above the WGS84 ellipsoid, and every file says so. Passing the
converter keeps this module free of the geodesy stack.

- GeoJSON (RFC 7946): a FeatureCollection with one Feature per track - a LineString
  (a Point for a one-point track) with ``[lon, lat, h]`` positions, in that order as the
  RFC demands - whose properties hold ``track_id``, ``class``, ``sensors``, ``gaps``
  (``[[t_start, t_end], ...]``), per-vertex ``times_s`` and local ``enu`` coordinates,
  and ``times_utc`` when an epoch is given; optionally one Point Feature per track point
  (``kind: "point"``) with its ``fix_indices``.
- CSV: one row per track point (columns :data:`TRACK_CSV_COLUMNS`).
- GPX 1.1: one ``<trk>`` per track, a new ``<trkseg>`` after every gap, ``<ele>`` the
  ellipsoidal height, ``<time>`` ISO 8601 UTC from a given epoch.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from typing import IO, Any
from xml.etree import ElementTree as ET

from .errors import TrackingError
from .tracking.types import Track

__all__ = [
    "GPX_NS",
    "TRACK_CSV_COLUMNS",
    "ToGeodetic",
    "iso_utc",
    "split_at_gaps",
    "tracks_to_geojson",
    "write_tracks_csv",
    "write_tracks_geojson",
    "write_tracks_gpx",
]

#: ``(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``, h above the WGS84 ellipsoid.
ToGeodetic = Callable[[float, float, float], tuple[float, float, float]]
GPX_NS = "http://www.topografix.com/GPX/1/1"
TRACK_CSV_COLUMNS = (
    "track_id",
    "class",
    "t_s",
    "time_utc",
    "e_m",
    "n_m",
    "u_m",
    "lat_deg",
    "lon_deg",
    "h_m",
    "sensors",
    "fix_indices",
    "cov_ee_m2",
    "cov_en_m2",
    "cov_nn_m2",
)
_HEIGHT_NOTE = "heights h_m / ele are metres above the WGS84 ellipsoid"

Dest = str | os.PathLike[str] | IO[str]


@contextmanager
def _open(dest: Dest, newline: str | None = None) -> Iterator[IO[str]]:
    if isinstance(dest, str | os.PathLike):
        with open(dest, "w", encoding="utf-8", newline=newline) as fh:
            yield fh
    else:
        yield dest


def _check_epoch(epoch: datetime | None) -> None:
    if epoch is not None and epoch.utcoffset() is None:
        raise TrackingError("epoch must be timezone-aware (e.g. datetime(..., tzinfo=UTC))")


def iso_utc(epoch: datetime, t_s: float) -> str:
    """ISO 8601 UTC time of ``epoch + t_s`` with millisecond precision, ``Z`` suffix."""
    _check_epoch(epoch)
    when = (epoch + timedelta(seconds=float(t_s))).astimezone(UTC)
    return when.strftime("%Y-%m-%dT%H:%M:%S.") + f"{when.microsecond // 1000:03d}Z"


def split_at_gaps(track: Track) -> list[list[int]]:
    """Point indices of the track's runs between gaps (each run non-empty)."""
    runs: list[list[int]] = []
    t = track.t_s
    for i in range(len(t)):
        if i == 0 or any(a <= t[i - 1] and t[i] <= b for a, b in track.gaps):
            runs.append([])
        runs[-1].append(i)
    return runs


def _geo(track: Track, to_geodetic: ToGeodetic) -> list[tuple[float, float, float]]:
    return [tuple(map(float, to_geodetic(*map(float, p)))) for p in track.p_enu]  # type: ignore[misc]


def tracks_to_geojson(
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    include_points: bool = False,
    epoch: datetime | None = None,
) -> dict[str, Any]:
    """Tracks as a GeoJSON FeatureCollection (a dict ready for :func:`json.dump`)."""
    _check_epoch(epoch)
    features: list[dict[str, Any]] = []
    for track in tracks:
        if not track.points:
            continue
        geo = _geo(track, to_geodetic)
        coords = [[lon, lat, h] for lat, lon, h in geo]
        geometry = (
            {"type": "Point", "coordinates": coords[0]}
            if len(coords) == 1
            else {"type": "LineString", "coordinates": coords}
        )
        props: dict[str, Any] = {
            "kind": "track",
            "track_id": track.id,
            "class": track.cls,
            "sensors": sorted(track.sensors),
            "gaps": [[a, b] for a, b in track.gaps],
            "times_s": [p.t_s for p in track.points],
            "enu": [[float(v) for v in p.p_enu] for p in track.points],
            "height": _HEIGHT_NOTE,
        }
        if epoch is not None:
            props["times_utc"] = [iso_utc(epoch, p.t_s) for p in track.points]
        features.append({"type": "Feature", "geometry": geometry, "properties": props})
        if include_points:
            for k, p in enumerate(track.points):
                pp: dict[str, Any] = {
                    "kind": "point",
                    "track_id": track.id,
                    "class": track.cls,
                    "t_s": p.t_s,
                    "sensors": list(p.sensors),
                    "fix_indices": list(p.fix_indices),
                    "enu": [float(v) for v in p.p_enu],
                }
                if epoch is not None:
                    pp["time_utc"] = iso_utc(epoch, p.t_s)
                features.append(
                    {
                        "type": "Feature",
                        "geometry": {"type": "Point", "coordinates": coords[k]},
                        "properties": pp,
                    }
                )
    return {"type": "FeatureCollection", "features": features}


def write_tracks_geojson(
    dest: Dest,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    include_points: bool = False,
    epoch: datetime | None = None,
) -> None:
    """Write :func:`tracks_to_geojson` to a file (UTF-8, strict JSON: no NaN)."""
    doc = tracks_to_geojson(tracks, to_geodetic, include_points=include_points, epoch=epoch)
    with _open(dest) as fh:
        json.dump(doc, fh, allow_nan=False)


def write_tracks_csv(
    dest: Dest,
    tracks: Iterable[Track],
    to_geodetic: ToGeodetic | None = None,
    *,
    epoch: datetime | None = None,
) -> None:
    """Write one CSV row per track point; geodetic and time columns empty without them."""
    _check_epoch(epoch)
    with _open(dest, newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(TRACK_CSV_COLUMNS)
        for track in tracks:
            for p in track.points:
                e, n, u = (float(v) for v in p.p_enu)
                geo = (
                    ("", "", "")
                    if to_geodetic is None
                    else tuple(repr(float(v)) for v in to_geodetic(e, n, u))
                )
                cov = (
                    ("", "", "")
                    if p.cov_xy is None
                    else (
                        repr(float(p.cov_xy[0, 0])),
                        repr(float(p.cov_xy[0, 1])),
                        repr(float(p.cov_xy[1, 1])),
                    )
                )
                writer.writerow(
                    [
                        track.id,
                        track.cls,
                        repr(p.t_s),
                        "" if epoch is None else iso_utc(epoch, p.t_s),
                        repr(e),
                        repr(n),
                        repr(u),
                        *geo,
                        ";".join(p.sensors),
                        ";".join(str(i) for i in p.fix_indices),
                        *cov,
                    ]
                )


def write_tracks_gpx(
    dest: Dest,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime,
    creator: str = "demtrack",
) -> None:
    """Write GPX 1.1: a ``<trk>`` per track, a ``<trkseg>`` per run between gaps.

    Parameters
    ----------
    dest : path or text file
        Output.
    tracks : sequence of Track
        Tracks.
    to_geodetic : callable
        Local frame -> ``(lat_deg, lon_deg, h_m)``.
    epoch : datetime
        Timezone-aware time of ``t_s = 0``.
    creator : str
        The GPX ``creator`` attribute.
    """
    _check_epoch(epoch)
    ET.register_namespace("", GPX_NS)
    q = f"{{{GPX_NS}}}"
    root = ET.Element(f"{q}gpx", {"version": "1.1", "creator": creator})
    meta = ET.SubElement(root, f"{q}metadata")
    ET.SubElement(meta, f"{q}desc").text = f"demtrack tracks; {_HEIGHT_NOTE}"
    ET.SubElement(meta, f"{q}time").text = iso_utc(epoch, 0.0)
    for track in tracks:
        if not track.points:
            continue
        geo = _geo(track, to_geodetic)
        trk = ET.SubElement(root, f"{q}trk")
        ET.SubElement(trk, f"{q}name").text = f"track {track.id}"
        ET.SubElement(trk, f"{q}desc").text = f"sensors: {', '.join(sorted(track.sensors))}"
        ET.SubElement(trk, f"{q}type").text = track.cls
        for run in split_at_gaps(track):
            seg = ET.SubElement(trk, f"{q}trkseg")
            for i in run:
                lat, lon, h = geo[i]
                pt = ET.SubElement(seg, f"{q}trkpt", {"lat": repr(lat), "lon": repr(lon)})
                ET.SubElement(pt, f"{q}ele").text = repr(h)
                ET.SubElement(pt, f"{q}time").text = iso_utc(epoch, track.points[i].t_s)
    tree = ET.ElementTree(root)
    ET.indent(tree)
    with _open(dest) as fh:
        fh.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        tree.write(fh, encoding="unicode")
        fh.write("\n")
