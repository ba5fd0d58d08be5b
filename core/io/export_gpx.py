"""GPX 1.1 track files, written with gpxpy.

One ``<trk>`` per track (``<name>`` "track N", ``<type>`` its class, ``<desc>`` its sensors
and id), a ``<trkseg>`` per run between gaps, every ``<trkpt>`` with ``<ele>`` (the
absolute height of :class:`~demtrack.core.io.export_common.HeightModel`: orthometric with a
geoid model, else ellipsoidal, as the metadata ``<desc>`` says) and ``<time>`` (ISO 8601
UTC, ``Z``; relative to the declared epoch when the store has no wall clock, as the
metadata says). gpxpy writes valid GPX numbers (never scientific notation) and escapes text.
"""

from __future__ import annotations

from collections.abc import Sequence

import gpxpy.gpx

from .export_common import ExportTrack, HeightModel, TimeBase

__all__ = ["GPX_NS", "gpx_text"]

GPX_NS = "http://www.topografix.com/GPX/1/1"


def gpx_text(
    tracks: Sequence[ExportTrack],
    heights: HeightModel,
    times: TimeBase,
    *,
    creator: str = "demtrack",
) -> str:
    """The GPX 1.1 document of ``tracks``.

    Parameters
    ----------
    tracks : sequence of ExportTrack
        Prepared tracks (:func:`~demtrack.core.io.export_common.prepare_tracks`).
    heights : HeightModel
        What ``<ele>`` is (said in the metadata).
    times : TimeBase
        What ``<time>`` is (said in the metadata).
    creator : str
        The ``creator`` attribute.

    Returns
    -------
    str
        The XML text.
    """
    gpx = gpxpy.gpx.GPX()
    gpx.creator = creator
    gpx.name = "demtrack tracks"
    gpx.description = f"demtrack tracks; {heights.note}; {times.note}"
    gpx.time = times.datetime(min((t.t_s[0] for t in tracks), default=0.0))
    for xt in tracks:
        track = xt.track
        trk = gpxpy.gpx.GPXTrack(
            name=f"track {track.id}",
            description=f"track_id {track.id}; sensors: {', '.join(sorted(track.sensors))}",
        )
        trk.type = track.cls  # type: ignore[assignment]  # gpxpy annotates it as None
        for run in xt.runs:
            seg = gpxpy.gpx.GPXTrackSegment()
            for i in run:
                seg.points.append(
                    gpxpy.gpx.GPXTrackPoint(
                        latitude=float(xt.lat_deg[i]),
                        longitude=float(xt.lon_deg[i]),
                        elevation=float(xt.abs_h_m[i]),
                        time=times.datetime(track.points[i].t_s),
                    )
                )
            trk.segments.append(seg)
        gpx.tracks.append(trk)
    return gpx.to_xml(version="1.1") + "\n"
