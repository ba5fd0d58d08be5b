"""Track files: GeoJSON, CSV, GPX 1.1, KML 2.2 and GeoPackage writers.

Geodetic output needs a converter ``to_geodetic(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``
from the local frame (the site's :class:`~demtrack.core.geo.geodesy.LocalFrame` provides one);
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
- KML 2.2: a ``<Placemark>`` per track (``<ExtendedData>`` with its id, class, sensors,
  times and gaps; a ``<TimeSpan>`` with an epoch) whose ``<MultiGeometry>`` holds a
  ``<LineString>`` per run between gaps (a ``<Point>`` for a one-point run);
  ``<coordinates>`` are ``lon,lat,h`` as KML demands, h the ellipsoidal height. KML's
  ``absolute`` altitude is above mean sea level, which demtrack does not know, so the
  geometry is ``clampToGround`` unless the caller says otherwise.
- GeoPackage (OGC 12-128r18, version 1.3), written with :mod:`sqlite3`: layer ``tracks``
  (``LINESTRING`` Z, one feature per track, EPSG:4326 lon/lat, z = ellipsoidal height;
  a one-point track repeats its point) and layer ``track_points`` (``POINT`` Z, one per
  track point), each with its properties; geometries are GeoPackage binary (header with
  the SRS id and envelope, then ISO WKB from shapely).
"""

from __future__ import annotations

import csv
import json
import os
import sqlite3
import struct
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import IO, Any
from xml.etree import ElementTree as ET

import numpy as np
import shapely

from ..errors import TrackingError
from ..tracking.types import Track

__all__ = [
    "GPKG_APPLICATION_ID",
    "GPX_NS",
    "KML_NS",
    "TRACK_CSV_COLUMNS",
    "ToGeodetic",
    "iso_utc",
    "split_at_gaps",
    "tracks_to_geojson",
    "write_tracks_csv",
    "write_tracks_geojson",
    "write_tracks_gpkg",
    "write_tracks_gpx",
    "write_tracks_kml",
]

#: ``(e_m, n_m, u_m) -> (lat_deg, lon_deg, h_m)``, h above the WGS84 ellipsoid.
ToGeodetic = Callable[[float, float, float], tuple[float, float, float]]
GPX_NS = "http://www.topografix.com/GPX/1/1"
KML_NS = "http://www.opengis.net/kml/2.2"
#: ``PRAGMA application_id`` of a GeoPackage: the ASCII bytes "GPKG".
GPKG_APPLICATION_ID = 0x47504B47
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


# ----------------------------------------------------------------------- KML
def _kml_coords(geo: Sequence[tuple[float, float, float]], idx: Sequence[int]) -> str:
    return " ".join(f"{geo[i][1]!r},{geo[i][0]!r},{geo[i][2]!r}" for i in idx)


def write_tracks_kml(
    dest: Dest,
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    altitude_mode: str = "clampToGround",
    name: str = "demtrack tracks",
) -> None:
    """Write KML 2.2: a Placemark per track, a LineString per run between gaps.

    Parameters
    ----------
    dest : path or text file
        Output.
    tracks : sequence of Track
        Tracks (empty ones are left out).
    to_geodetic : callable
        Local frame -> ``(lat_deg, lon_deg, h_m)``, h above the WGS84 ellipsoid.
    epoch : datetime, optional
        Timezone-aware time of ``t_s = 0``; adds a ``<TimeSpan>`` to each track.
    altitude_mode : {"clampToGround", "absolute", "relativeToGround"}
        KML altitude mode of the geometry. ``coordinates`` always carry the ellipsoidal
        height; ``absolute`` would read it as a height above mean sea level.
    name : str
        The document's name.
    """
    _check_epoch(epoch)
    if altitude_mode not in ("clampToGround", "absolute", "relativeToGround"):
        raise TrackingError(f"unknown KML altitude mode {altitude_mode!r}")
    ET.register_namespace("", KML_NS)
    q = f"{{{KML_NS}}}"
    root = ET.Element(f"{q}kml")
    doc = ET.SubElement(root, f"{q}Document")
    ET.SubElement(doc, f"{q}name").text = name
    ET.SubElement(
        doc, f"{q}description"
    ).text = f"demtrack tracks; coordinates are lon,lat,h; {_HEIGHT_NOTE}"
    for track in tracks:
        if not track.points:
            continue
        geo = _geo(track, to_geodetic)
        t = [p.t_s for p in track.points]
        pm = ET.SubElement(doc, f"{q}Placemark", {"id": f"track-{track.id}"})
        ET.SubElement(pm, f"{q}name").text = f"track {track.id}"
        ET.SubElement(
            pm, f"{q}description"
        ).text = (
            f"{track.cls}; sensors: {', '.join(sorted(track.sensors))}; {len(track.gaps)} gap(s)"
        )
        if epoch is not None:
            span = ET.SubElement(pm, f"{q}TimeSpan")
            ET.SubElement(span, f"{q}begin").text = iso_utc(epoch, t[0])
            ET.SubElement(span, f"{q}end").text = iso_utc(epoch, t[-1])
        data = ET.SubElement(pm, f"{q}ExtendedData")
        fields = {
            "track_id": str(track.id),
            "class": track.cls,
            "sensors": ",".join(sorted(track.sensors)),
            "t_start_s": repr(t[0]),
            "t_end_s": repr(t[-1]),
            "n_points": str(len(t)),
            "gaps": json.dumps([[a, b] for a, b in track.gaps]),
        }
        for key, value in fields.items():
            d = ET.SubElement(data, f"{q}Data", {"name": key})
            ET.SubElement(d, f"{q}value").text = value
        multi = ET.SubElement(pm, f"{q}MultiGeometry")
        for run in split_at_gaps(track):
            kind = "LineString" if len(run) > 1 else "Point"
            g = ET.SubElement(multi, f"{q}{kind}")
            ET.SubElement(g, f"{q}altitudeMode").text = altitude_mode
            ET.SubElement(g, f"{q}coordinates").text = _kml_coords(geo, run)
    tree = ET.ElementTree(root)
    ET.indent(tree)
    with _open(dest) as fh:
        fh.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        tree.write(fh, encoding="unicode")
        fh.write("\n")


# ---------------------------------------------------------------- GeoPackage
_WGS84_WKT = (
    'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563,'
    'AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,'
    'AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],'
    'AXIS["Latitude",NORTH],AXIS["Longitude",EAST],AUTHORITY["EPSG","4326"]]'
)
_GPKG_SCHEMA = """
CREATE TABLE gpkg_spatial_ref_sys (
    srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, organization TEXT NOT NULL,
    organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
CREATE TABLE gpkg_contents (
    table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
    description TEXT DEFAULT '',
    last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
    min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
    CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
CREATE TABLE gpkg_geometry_columns (
    table_name TEXT NOT NULL, column_name TEXT NOT NULL, geometry_type_name TEXT NOT NULL,
    srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL,
    CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
    CONSTRAINT uk_gc_table_name UNIQUE (table_name),
    CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
    CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
CREATE TABLE tracks (
    fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom LINESTRING,
    track_id INTEGER NOT NULL, class TEXT NOT NULL, sensors TEXT NOT NULL,
    t_start_s DOUBLE NOT NULL, t_end_s DOUBLE NOT NULL, time_start_utc DATETIME,
    time_end_utc DATETIME, n_points INTEGER NOT NULL, n_gaps INTEGER NOT NULL,
    gaps TEXT NOT NULL);
CREATE TABLE track_points (
    fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom POINT,
    track_id INTEGER NOT NULL, class TEXT NOT NULL, t_s DOUBLE NOT NULL, time_utc DATETIME,
    sensors TEXT NOT NULL, fix_indices TEXT NOT NULL,
    e_m DOUBLE NOT NULL, n_m DOUBLE NOT NULL, u_m DOUBLE NOT NULL)
"""


def _gpkg_geometry(geom: shapely.Geometry, srs_id: int = 4326) -> bytes:
    """GeoPackage binary: ``GP``, version 0, flags, SRS id, xy envelope, ISO WKB (LE)."""
    if isinstance(geom, shapely.Point):
        envelope, flags = b"", 0b0000_0001  # no envelope, little endian
    else:
        x0, y0, x1, y1 = geom.bounds
        envelope, flags = struct.pack("<4d", x0, x1, y0, y1), 0b0000_0011  # xy envelope
    header = b"GP" + struct.pack("<BBi", 0, flags, srs_id)
    wkb = shapely.to_wkb(geom, byte_order=1, flavor="iso", output_dimension=3)
    return header + envelope + wkb


def write_tracks_gpkg(
    path: str | os.PathLike[str],
    tracks: Sequence[Track],
    to_geodetic: ToGeodetic,
    *,
    epoch: datetime | None = None,
    include_points: bool = True,
) -> None:
    """Write a GeoPackage with layers ``tracks`` (LineString Z) and ``track_points``.

    Parameters
    ----------
    path : path
        Output file (replaced if it exists).
    tracks : sequence of Track
        Tracks (empty ones are left out).
    to_geodetic : callable
        Local frame -> ``(lat_deg, lon_deg, h_m)``; geometries are EPSG:4326 ``(lon,
        lat)`` with z the height above the WGS84 ellipsoid.
    epoch : datetime, optional
        Timezone-aware time of ``t_s = 0``; fills the ``time_*_utc`` columns.
    include_points : bool
        Fill the ``track_points`` layer (it is created either way).
    """
    _check_epoch(epoch)
    path = Path(path)
    path.unlink(missing_ok=True)
    conn = sqlite3.connect(path)
    try:
        conn.execute(f"PRAGMA application_id = {GPKG_APPLICATION_ID}")
        conn.execute("PRAGMA user_version = 10300")
        with conn:
            for stmt in _GPKG_SCHEMA.split(";"):
                conn.execute(stmt)
            conn.executemany(
                "INSERT INTO gpkg_spatial_ref_sys VALUES (?,?,?,?,?,?)",
                [
                    ("WGS 84 geodetic", 4326, "EPSG", 4326, _WGS84_WKT, "longitude/latitude"),
                    ("Undefined cartesian SRS", -1, "NONE", -1, "undefined", "undefined"),
                    ("Undefined geographic SRS", 0, "NONE", 0, "undefined", "undefined"),
                ],
            )
            when = lambda t: None if epoch is None else iso_utc(epoch, t)  # noqa: E731
            lines, points, all_xy = [], [], []
            for track in tracks:
                if not track.points:
                    continue
                geo = np.array(_geo(track, to_geodetic))
                xyz = geo[:, [1, 0, 2]]  # lon, lat, h
                all_xy.append(xyz[:, :2])
                line = shapely.LineString(xyz if len(xyz) > 1 else np.vstack([xyz, xyz]))
                t = [p.t_s for p in track.points]
                lines.append(
                    (
                        _gpkg_geometry(line),
                        track.id,
                        track.cls,
                        ",".join(sorted(track.sensors)),
                        t[0],
                        t[-1],
                        when(t[0]),
                        when(t[-1]),
                        len(t),
                        len(track.gaps),
                        json.dumps([[a, b] for a, b in track.gaps]),
                    )
                )
                if not include_points:
                    continue
                for k, p in enumerate(track.points):
                    e, n, u = (float(v) for v in p.p_enu)
                    points.append(
                        (
                            _gpkg_geometry(shapely.Point(xyz[k])),
                            track.id,
                            track.cls,
                            p.t_s,
                            when(p.t_s),
                            ",".join(p.sensors),
                            ",".join(str(i) for i in p.fix_indices),
                            e,
                            n,
                            u,
                        )
                    )
            conn.executemany(
                "INSERT INTO tracks (geom, track_id, class, sensors, t_start_s, t_end_s,"
                " time_start_utc, time_end_utc, n_points, n_gaps, gaps)"
                " VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                lines,
            )
            conn.executemany(
                "INSERT INTO track_points (geom, track_id, class, t_s, time_utc, sensors,"
                " fix_indices, e_m, n_m, u_m) VALUES (?,?,?,?,?,?,?,?,?,?)",
                points,
            )
            xy = np.vstack(all_xy) if all_xy else None
            box = (None,) * 4 if xy is None else (*xy.min(axis=0), *xy.max(axis=0))
            box = tuple(None if v is None else float(v) for v in box)
            for table, kind in (("tracks", "LINESTRING"), ("track_points", "POINT")):
                conn.execute(
                    "INSERT INTO gpkg_contents (table_name, data_type, identifier, description,"
                    " min_x, min_y, max_x, max_y, srs_id) VALUES (?,?,?,?,?,?,?,?,?)",
                    (table, "features", table, f"demtrack {table}; {_HEIGHT_NOTE}", *box, 4326),
                )
                conn.execute(
                    "INSERT INTO gpkg_geometry_columns VALUES (?,?,?,?,?,?)",
                    (table, "geom", kind, 4326, 1, 0),
                )
    finally:
        conn.close()
