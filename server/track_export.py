"""Stored track bodies written as files: GeoJSON, CSV, GPX, KML, KMZ and GeoPackage.

The one writer per format is :mod:`demtrack.core.io.track_io`'s (``demtrack track -o``
uses the same); this module turns the server's stored (possibly clipped) bodies into
:class:`~demtrack.core.tracking.types.Track` values, chooses the heights and times, and
picks the writer. The console's export menu downloads from here.

Heights: GeoJSON z, GeoPackage z and ``h_wgs84_m`` are ellipsoidal; KML ``absolute``, GPX
``<ele>`` and ``elevation_m`` are orthometric in the site's vertical datum, by the same
rule as the console's readout (:func:`~demtrack.server.site_info.sea_level_geoid`: the
geoid ``site.json`` states, evaluated at each point, e.g. EGM96; EGM96 for a site that
states none, when its grid is installed), else none: then those heights are the
ellipsoidal ones, and every file says so.

Times: the store keeps session seconds ``t_s`` with no wall clock, so each file's times are
``epoch + t_s`` with the epoch declared in the file: the ``epoch`` parameter, else the UNIX
epoch (1970-01-01T00:00:00Z, which is right as soon as ``t_s`` are UNIX seconds).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.errors import InputFileError
from demtrack.core.io.times import parse_iso_time
from demtrack.core.io.track_io import (
    TRACK_CSVT,
    TRACK_FORMATS,
    UNIX_EPOCH,
    HeightModel,
    TimeBase,
    track_file_bytes,
    write_tracks,
)
from demtrack.core.tracking.types import Track, TrackPoint

from .site_info import sea_level_geoid

__all__ = [
    "EXPORT_TYPES",
    "export_bytes",
    "parse_epoch",
    "site_heights",
    "time_base",
    "track_from_body",
    "write_track_file",
]

#: Export format -> (media type, file suffix).
EXPORT_TYPES: dict[str, tuple[str, str]] = {
    name: (f.media_type, f.suffix) for name, f in TRACK_FORMATS.items()
}


def track_from_body(body: dict[str, Any]) -> Track:
    """A :class:`Track` value from a stored (possibly clipped) track body."""
    points = [
        TrackPoint(p["t_s"], [p["e_m"], p["n_m"], p["u_m"]], p["sensors"], p["detection_ids"])
        for p in body["points"]
    ]
    return Track(body["id"], body["cls"], points, body["sensors"], [tuple(g) for g in body["gaps"]])


def parse_epoch(text: str | None) -> datetime | None:
    """The UTC time of ``t = 0 s`` from ISO 8601 ``text`` with a zone; None when not given.

    :class:`~demtrack.core.errors.TimeFormatError` (a :class:`QueryError`, 422) when
    ``text`` is not ISO 8601 or has no zone.
    """
    if text is None:
        return None
    t_s = parse_iso_time(text, "epoch")
    return UNIX_EPOCH + timedelta(seconds=t_s)


def time_base(
    epoch: datetime | None, *, wall_clock: bool | None = None, t_s: Sequence[float] = ()
) -> TimeBase:
    """The exports' times: ``epoch + t_s``; without an epoch, the store's UNIX seconds.

    ``wall_clock`` None: decided by :meth:`TimeBase.for_times` from the exported ``t_s``
    (UNIX seconds are clock times; a store of session seconds, all before 2000, is
    declared relative to 1970-01-01T00:00:00Z). A given epoch is a declared one.
    """
    if wall_clock is None:
        return TimeBase.for_times(list(t_s), epoch)
    return TimeBase(UNIX_EPOCH if epoch is None else epoch, wall_clock=wall_clock)


def site_heights(site: Any, *, egm96: bool = True) -> HeightModel:
    """The exports' sea-level heights at ``site``, by the readout's rule.

    The site's vertical datum (:func:`~demtrack.server.site_info.sea_level_geoid`: its
    geoid evaluated at each point; EGM96 for a site that states none, when installed),
    else none (ellipsoidal, declared). ``egm96=False`` never adds EGM96 to a site that
    states no geoid (only its stated model, or its constant ``geoid_undulation_m``).
    """
    if egm96:
        return HeightModel.from_geoid(sea_level_geoid(site))
    geoid = getattr(site, "geoid", None)
    if geoid is not None:
        return HeightModel.from_geoid(geoid)
    return HeightModel.for_site(getattr(site, "geoid_undulation_m", 0.0))


def export_bytes(
    fmt: str,
    bodies: list[dict[str, Any]],
    frame: Any,
    epoch: datetime | TimeBase | None = None,
    heights: HeightModel | None = None,
) -> bytes:
    """The file of format ``fmt`` (a key of :data:`EXPORT_TYPES`) holding ``bodies``.

    ``frame``: the site's :class:`~demtrack.core.geo.geodesy.LocalFrame`, for points the
    bodies do not carry geodetic coordinates of; ``epoch``: the time of ``t_s = 0`` (or a
    whole :class:`TimeBase`); ``heights``: the geoid model (none: ellipsoidal, declared).
    """
    tracks = [track_from_body(b) for b in bodies]
    # The stored points carry their geodetic coordinates: look them up, convert the rest.
    known = {
        (p["e_m"], p["n_m"], p["u_m"]): (p["lat_deg"], p["lon_deg"], p["h_m"])
        for b in bodies
        for p in b["points"]
    }

    def to_geodetic(e: float, n: float, u: float) -> tuple[float, float, float]:
        hit = known.get((e, n, u))
        if hit is not None:
            return hit
        lat, lon, h = (float(np.asarray(v)) for v in frame.to_geodetic(e, n, u))
        return lat, lon, h

    if isinstance(epoch, TimeBase):
        times = epoch
    else:
        times = time_base(epoch, t_s=[p["t_s"] for b in bodies for p in b["points"]])
    return track_file_bytes(fmt, tracks, to_geodetic, times=times, heights=heights)


#: Track file suffix -> writer format (``demtrack track -o``, ``demtrack reprocess``).
FILE_FORMATS = {
    ".geojson": "geojson", ".json": "geojson", ".csv": "csv", ".gpx": "gpx", ".kml": "kml",
    ".kmz": "kmz", ".gpkg": "gpkg",
}  # fmt: skip


def write_track_file(
    site: Any,
    tracks: Sequence[Track],
    out: Path,
    epoch: datetime | None = None,
    *,
    batch_geodetic: bool = False,
) -> None:
    """Write ``tracks`` to ``out`` in its suffix's format (and a ``.csvt`` beside a CSV).

    Heights by :func:`site_heights`; times real UTC when they are UNIX seconds, else
    relative to ``epoch`` (declared in the file). ``batch_geodetic``: convert each
    track's points to WGS84 in one call (fast for millions of points; the last bits may
    differ from one-point calls, numpy's other matrix path, which ``demtrack track``
    keeps).
    """
    fmt = FILE_FORMATS.get(out.suffix.lower())
    if fmt is None:
        known = ", ".join(FILE_FORMATS)
        raise InputFileError(f"unknown track file type {out.suffix.lower()!r} (use {known})")
    frame = site.frame
    known_points: dict[tuple[float, ...], tuple[float, float, float]] = {}
    if batch_geodetic:
        for t in tracks:
            enu = [tuple(float(c) for c in p.p_enu) for p in t.points]
            if enu:
                e, n, u = zip(*enu, strict=True)
                lat, lon, h = (np.atleast_1d(a).tolist() for a in frame.to_geodetic(e, n, u))
                known_points.update(zip(enu, zip(lat, lon, h, strict=True), strict=True))

    def to_geodetic(e: float, n: float, u: float) -> tuple[float, float, float]:
        got = known_points.get((e, n, u))
        if got is not None:
            return got
        lat, lon, h = frame.to_geodetic(e, n, u)
        return float(lat), float(lon), float(h)

    # Real UTC when the times are UNIX seconds; session seconds (a declared epoch, or
    # all before 2000) are said to be relative in the file.
    times = TimeBase.for_times([p.t_s for t in tracks for p in t.points], epoch)
    heights = site_heights(site)  # the readout's rule: EGM96, else the site's N, else none
    write_tracks(fmt, out, tracks, to_geodetic, times=times, heights=heights)
    if fmt == "csv":
        # GDAL's column types for the CSV, beside it (ogr reads x.csvt with x.csv).
        out.with_suffix(".csvt").write_text(TRACK_CSVT, encoding="utf-8")
