"""Track files, one writer per format: GeoJSON, CSV, GPX 1.1, KML 2.2, KMZ and GeoPackage.

The server's ``/api/tracks/export`` (and so the console's export menu) and the
``demtrack track -o`` command write with these functions and nothing else.

Geodetic output needs a converter ``to_geodetic(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``
from the local frame (the site's :class:`~demtrack.core.geo.geodesy.LocalFrame` provides
one); ``h_m`` is the height above the WGS84 ellipsoid. Sea-level heights come from a
:class:`~demtrack.core.io.export_common.HeightModel` (none: the ellipsoidal height is
written where a format wants sea level, and the file says so), times from a
:class:`~demtrack.core.io.export_common.TimeBase` (``epoch + t_s``, the epoch declared in
every file). A run of points between two gaps is its own segment in every format.

- GeoJSON (RFC 7946, here): a FeatureCollection, one Feature per track, a
  ``MultiLineString`` (one line per run; a one-point run is its point twice) with
  ``[lon, lat, h]`` positions, h ellipsoidal as the RFC says; properties ``track_id``,
  ``class``, ``sensors``, ``gaps``, per-vertex ``times_s``, ``times_utc``, ``enu``,
  ``h_wgs84_m`` (= z) and, with a geoid model, ``elevation_m`` (orthometric) with its
  ``elevation_datum`` (``"EGM96 geoid"``); optionally a Point Feature per track point.
- CSV (here, :mod:`csv`): one row per point, columns :data:`TRACK_CSV_COLUMNS` with
  ``longitude``/``latitude`` that QGIS detects and GDAL reads with
  ``-oo X_POSSIBLE_NAMES=longitude -oo Y_POSSIBLE_NAMES=latitude``; :data:`TRACK_CSVT` is
  the matching GDAL ``.csvt`` (column types); ``mgrs`` is each point's 1 m MGRS
  reference (:func:`~demtrack.core.geo.grid_ref.mgrs_of`; empty at the poles).
- GPX: :mod:`~demtrack.core.io.export_gpx` (gpxpy).
- KML / KMZ: :mod:`~demtrack.core.io.export_kml` (``gx:Track``, ``absolute``).
- GeoPackage: :mod:`~demtrack.core.io.export_gpkg` (GDAL through pyogrio, R-tree index).
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import IO, Any

from ..errors import GeodesyError, TrackingError
from ..geo.grid_ref import mgrs_of
from ..tracking.types import Track
from .export_common import (
    UNIX_EPOCH,
    ExportTrack,
    HeightModel,
    TimeBase,
    ToGeodetic,
    iso_utc,
    prepare_tracks,
    split_at_gaps,
)
from .export_gpkg import GPKG_APPLICATION_ID, GPKG_CRS, write_gpkg
from .export_gpx import GPX_NS, gpx_text
from .export_kml import GX_NS, KML_NS, kml_text, kmz_bytes

__all__ = [
    "GPKG_APPLICATION_ID",
    "GPKG_CRS",
    "GPX_NS",
    "GX_NS",
    "KML_NS",
    "TRACK_CSVT",
    "TRACK_CSV_COLUMNS",
    "TRACK_FORMATS",
    "UNIX_EPOCH",
    "HeightModel",
    "TimeBase",
    "ToGeodetic",
    "TrackFormat",
    "iso_utc",
    "split_at_gaps",
    "track_file_bytes",
    "tracks_to_geojson",
    "write_tracks",
    "write_tracks_csv",
    "write_tracks_geojson",
    "write_tracks_gpkg",
    "write_tracks_gpx",
    "write_tracks_kml",
    "write_tracks_kmz",
]

TRACK_CSV_COLUMNS = (
    "track_id",
    "class",
    "segment",
    "time_utc",
    "t_s",
    "longitude",
    "latitude",
    "h_wgs84_m",
    "elevation_m",
    "elevation_datum",
    "mgrs",
    "e_m",
    "n_m",
    "u_m",
    "sensors",
    "fix_indices",
    "cov_ee_m2",
    "cov_en_m2",
    "cov_nn_m2",
)
#: GDAL's ``.csvt`` for :data:`TRACK_CSV_COLUMNS` (one type per column, in order).
TRACK_CSVT = (
    '"Integer","String","Integer","DateTime","Real","Real","Real","Real","Real","String",'
    '"String","Real","Real","Real","String","String","Real","Real","Real"\n'
)
_ELLIPSOID_NOTE = "h / h_wgs84_m / GeoJSON z are metres above the WGS84 ellipsoid"

Dest = str | os.PathLike[str] | IO[str]


@dataclass(frozen=True)
class TrackFormat:
    """An export format: media type, file suffix, and whether the file is binary."""

    media_type: str
    suffix: str
    binary: bool = False


#: Export format -> how it is served and named.
TRACK_FORMATS: dict[str, TrackFormat] = {
    "geojson": TrackFormat("application/geo+json", ".geojson"),
    "csv": TrackFormat("text/csv; charset=utf-8", ".csv"),
    "gpx": TrackFormat("application/gpx+xml", ".gpx"),
    "kml": TrackFormat("application/vnd.google-earth.kml+xml", ".kml"),
    "kmz": TrackFormat("application/vnd.google-earth.kmz", ".kmz", binary=True),
    "gpkg": TrackFormat("application/geopackage+sqlite3", ".gpkg", binary=True),
}


@contextmanager
def _open(dest: Dest, newline: str | None = None) -> Iterator[IO[str]]:
    if isinstance(dest, str | os.PathLike):
        with open(dest, "w", encoding="utf-8", newline=newline) as fh:
            yield fh
    else:
        yield dest


def _bases(
    epoch: datetime | None, times: TimeBase | None, heights: HeightModel | None
) -> tuple[HeightModel, TimeBase]:
    if times is not None and epoch is not None:
        raise TrackingError("give either epoch or times, not both")
    if times is None:
        times = TimeBase(UNIX_EPOCH if epoch is None else epoch)
    return heights or HeightModel(), times


# ------------------------------------------------------------------ GeoJSON
def _multiline(xt: ExportTrack) -> list[list[list[float]]]:
    lines = []
    for run in xt.runs:
        line = [[float(xt.lon_deg[i]), float(xt.lat_deg[i]), float(xt.h_m[i])] for i in run]
        lines.append(line if len(line) > 1 else line * 2)
    return lines


def tracks_to_geojson(
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    include_points: bool = False,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> dict[str, Any]:
    """Tracks as a GeoJSON FeatureCollection (a dict ready for :func:`json.dump`)."""
    hm, tb = _bases(epoch, times, heights)
    features: list[dict[str, Any]] = []
    for xt in prepare_tracks(tracks, to_geodetic, hm, tb):
        track = xt.track
        props: dict[str, Any] = {
            "kind": "track",
            "track_id": track.id,
            "class": track.cls,
            "sensors": sorted(track.sensors),
            "gaps": [[a, b] for a, b in track.gaps],
            "n_segments": len(xt.runs),
            "times_s": xt.t_s,
            "times_utc": list(xt.times_utc),
            "epoch_utc": tb.epoch_iso,
            "wall_clock": tb.wall_clock,
            "enu": [[float(v) for v in p.p_enu] for p in track.points],
            "height": f"{_ELLIPSOID_NOTE}; {hm.note}",
            "time": tb.note,
            "h_wgs84_m": [float(v) for v in xt.h_m],
        }
        if hm.orthometric:
            props["elevation_m"] = [float(v) for v in xt.abs_h_m]
            props["elevation_datum"] = hm.datum_name
        geometry = {"type": "MultiLineString", "coordinates": _multiline(xt)}
        features.append({"type": "Feature", "geometry": geometry, "properties": props})
        if not include_points:
            continue
        for k, p in enumerate(track.points):
            pp: dict[str, Any] = {
                "kind": "point",
                "track_id": track.id,
                "class": track.cls,
                "t_s": p.t_s,
                "time_utc": xt.times_utc[k],
                "sensors": list(p.sensors),
                "fix_indices": list(p.fix_indices),
                "enu": [float(v) for v in p.p_enu],
                "h_wgs84_m": float(xt.h_m[k]),
            }
            if hm.orthometric:
                pp["elevation_m"] = float(xt.abs_h_m[k])
                pp["elevation_datum"] = hm.datum_name
            coords = [float(xt.lon_deg[k]), float(xt.lat_deg[k]), float(xt.h_m[k])]
            features.append(
                {
                    "type": "Feature",
                    "geometry": {"type": "Point", "coordinates": coords},
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
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> None:
    """Write :func:`tracks_to_geojson` to a file (UTF-8, strict JSON: no NaN)."""
    doc = tracks_to_geojson(
        tracks,
        to_geodetic,
        include_points=include_points,
        epoch=epoch,
        times=times,
        heights=heights,
    )
    with _open(dest) as fh:
        json.dump(doc, fh, allow_nan=False)


# ---------------------------------------------------------------------- CSV
def _mgrs_or_empty(lat_deg: float, lon_deg: float) -> str:
    """The point's 1 m MGRS reference; empty at the poles (UPS is not supported)."""
    try:
        return mgrs_of(lat_deg, lon_deg)
    except GeodesyError:
        return ""


def write_tracks_csv(
    dest: Dest,
    tracks: Iterable[Track],
    to_geodetic: ToGeodetic | None = None,
    *,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> None:
    """Write one CSV row per track point (columns :data:`TRACK_CSV_COLUMNS`).

    Without ``to_geodetic`` the geodetic columns are empty. ``h_wgs84_m`` is above the
    WGS84 ellipsoid; ``elevation_m`` above the geoid that ``elevation_datum`` names
    (``"EGM96 geoid"``), both empty without a geoid model; ``segment`` numbers the runs
    between gaps from 0.
    """
    hm, tb = _bases(epoch, times, heights)
    tracks = list(tracks)
    with _open(dest, newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(TRACK_CSV_COLUMNS)
        prepared = prepare_tracks(tracks, to_geodetic, hm, tb) if to_geodetic is not None else None
        nonempty = [t for t in tracks if t.points]
        for n, track in enumerate(nonempty):
            xt = prepared[n] if prepared is not None else None
            runs = xt.runs if xt is not None else tuple(map(tuple, split_at_gaps(track)))
            segment = {i: k for k, run in enumerate(runs) for i in run}
            for i, p in enumerate(track.points):
                e, n_m, u = (float(v) for v in p.p_enu)
                if xt is None:
                    geo = ["", "", "", "", "", ""]
                else:
                    geo = [
                        repr(float(xt.lon_deg[i])),
                        repr(float(xt.lat_deg[i])),
                        repr(float(xt.h_m[i])),
                        repr(float(xt.abs_h_m[i])) if hm.orthometric else "",
                        hm.datum_name if hm.orthometric else "",
                        _mgrs_or_empty(float(xt.lat_deg[i]), float(xt.lon_deg[i])),
                    ]
                cov = (
                    ["", "", ""]
                    if p.cov_xy is None
                    else [
                        repr(float(p.cov_xy[0, 0])),
                        repr(float(p.cov_xy[0, 1])),
                        repr(float(p.cov_xy[1, 1])),
                    ]
                )
                writer.writerow(
                    [
                        track.id,
                        track.cls,
                        segment[i],
                        tb.iso(p.t_s),
                        repr(p.t_s),
                        *geo,
                        repr(e),
                        repr(n_m),
                        repr(u),
                        ";".join(p.sensors),
                        ";".join(str(j) for j in p.fix_indices),
                        *cov,
                    ]
                )


# ------------------------------------------------------- GPX, KML, KMZ, GPKG
def write_tracks_gpx(
    dest: Dest,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
    creator: str = "demtrack",
) -> None:
    """Write GPX 1.1 (:func:`~demtrack.core.io.export_gpx.gpx_text`)."""
    hm, tb = _bases(epoch, times, heights)
    text = gpx_text(prepare_tracks(tracks, to_geodetic, hm, tb), hm, tb, creator=creator)
    with _open(dest) as fh:
        fh.write(text)


def write_tracks_kml(
    dest: Dest,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
    name: str = "demtrack tracks",
) -> None:
    """Write KML 2.2 (:func:`~demtrack.core.io.export_kml.kml_text`)."""
    hm, tb = _bases(epoch, times, heights)
    text = kml_text(prepare_tracks(tracks, to_geodetic, hm, tb), hm, tb, name=name)
    with _open(dest) as fh:
        fh.write(text)


def write_tracks_kmz(
    path: str | os.PathLike[str],
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> None:
    """Write the KML of :func:`write_tracks_kml` as a KMZ archive (``doc.kml``)."""
    hm, tb = _bases(epoch, times, heights)
    text = kml_text(prepare_tracks(tracks, to_geodetic, hm, tb), hm, tb)
    Path(path).write_bytes(kmz_bytes(text))


def write_tracks_gpkg(
    path: str | os.PathLike[str],
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
    include_points: bool = True,
) -> None:
    """Write a GeoPackage (:func:`~demtrack.core.io.export_gpkg.write_gpkg`)."""
    hm, tb = _bases(epoch, times, heights)
    prepared = prepare_tracks(tracks, to_geodetic, hm, tb)
    write_gpkg(path, prepared, hm, tb, include_points=include_points)


#: The writer of each format (text ones take a file or a text stream, binary ones a path).
_WRITERS: dict[str, Callable[..., None]] = {
    "geojson": write_tracks_geojson,
    "csv": write_tracks_csv,
    "gpx": write_tracks_gpx,
    "kml": write_tracks_kml,
    "kmz": write_tracks_kmz,
    "gpkg": write_tracks_gpkg,
}


def write_tracks(
    fmt: str,
    path: str | os.PathLike[str],
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> None:
    """Write ``tracks`` to ``path`` in format ``fmt`` (a key of :data:`TRACK_FORMATS`)."""
    if fmt not in TRACK_FORMATS:
        raise TrackingError(f"unknown track format {fmt!r} (use {', '.join(TRACK_FORMATS)})")
    _WRITERS[fmt](path, tracks, to_geodetic, times=times, heights=heights)


def track_file_bytes(
    fmt: str,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    times: TimeBase | None = None,
    heights: HeightModel | None = None,
) -> bytes:
    """The bytes of the file :func:`write_tracks` would write."""
    if fmt not in TRACK_FORMATS:
        raise TrackingError(f"unknown track format {fmt!r} (use {', '.join(TRACK_FORMATS)})")
    if TRACK_FORMATS[fmt].binary:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"tracks{TRACK_FORMATS[fmt].suffix}"
            write_tracks(fmt, path, tracks, to_geodetic, times=times, heights=heights)
            return path.read_bytes()
    buf = io.StringIO()
    _WRITERS[fmt](buf, tracks, to_geodetic, times=times, heights=heights)
    return buf.getvalue().encode("utf-8")
