"""KML 2.2 / KMZ track files with ``gx:Track``, so tracks animate in Google Earth.

One ``<Placemark>`` per track: ``<name>`` "track N", a ``<description>``, a ``<TimeSpan>``
(first to last point), ``<ExtendedData>`` (id, class, sensors, times, gaps, epoch) and a
``<gx:MultiTrack>`` (``gx:interpolate`` 0) holding one ``<gx:Track>`` per run between gaps,
so nothing is drawn across a gap. Each ``gx:Track`` has ``altitudeMode`` ``absolute``, one
``<when>`` (ISO 8601 UTC) and one ``<gx:coord>`` (``lon lat alt``) per point; ``alt`` is the
absolute height of :class:`~demtrack.core.io.export_common.HeightModel` (orthometric with
a geoid model; without one the ellipsoidal height, as the document's description says).

Written with :mod:`xml.etree.ElementTree` rather than simplekml: simplekml writes a
``gx:Track``'s ``altitudeMode`` after its coordinates (the schema puts it first), keeps
process-wide mutable state while it renders (ids from one global counter, the root being
compiled) that the server's worker threads would share, and numbers its ids afresh on every
call, so the same tracks would not give the same bytes. KMZ is the KML as ``doc.kml`` in a
ZIP archive (:mod:`zipfile`), dated 1980-01-01 so the bytes depend on the tracks only.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Sequence
from xml.etree import ElementTree as ET

from .export_common import ExportTrack, HeightModel, TimeBase

__all__ = ["GX_NS", "KML_NS", "kml_text", "kmz_bytes"]

KML_NS = "http://www.opengis.net/kml/2.2"
GX_NS = "http://www.google.com/kml/ext/2.2"
_K = f"{{{KML_NS}}}"
_G = f"{{{GX_NS}}}"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def kml_text(
    tracks: Sequence[ExportTrack],
    heights: HeightModel,
    times: TimeBase,
    *,
    name: str = "demtrack tracks",
) -> str:
    """The KML 2.2 document of ``tracks`` (``gx:Track`` per run, ``absolute`` heights).

    Parameters
    ----------
    tracks : sequence of ExportTrack
        Prepared tracks (:func:`~demtrack.core.io.export_common.prepare_tracks`).
    heights : HeightModel
        What the altitudes are (said in the description).
    times : TimeBase
        What the ``<when>`` times are (said in the description).
    name : str
        The document's name.

    Returns
    -------
    str
        The XML text.
    """
    ET.register_namespace("", KML_NS)
    ET.register_namespace("gx", GX_NS)
    root = ET.Element(f"{_K}kml")
    doc = _sub(root, f"{_K}Document")
    _sub(doc, f"{_K}name", name)
    _sub(
        doc,
        f"{_K}description",
        f"demtrack tracks; gx:coord is lon lat alt; {heights.note}; {times.note}",
    )
    style = _sub(doc, f"{_K}Style", id="track")
    line = _sub(style, f"{_K}LineStyle")
    _sub(line, f"{_K}color", "ff00aaff")
    _sub(line, f"{_K}width", "3")
    for xt in tracks:
        track = xt.track
        t = xt.t_s
        pm = _sub(doc, f"{_K}Placemark", id=f"track-{track.id}")
        _sub(pm, f"{_K}name", f"track {track.id}")
        _sub(
            pm,
            f"{_K}description",
            f"{track.cls}; sensors: {', '.join(sorted(track.sensors))};"
            f" {len(xt.runs)} segment(s), {len(track.gaps)} gap(s)",
        )
        span = _sub(pm, f"{_K}TimeSpan")
        _sub(span, f"{_K}begin", xt.times_utc[0])
        _sub(span, f"{_K}end", xt.times_utc[-1])
        _sub(pm, f"{_K}styleUrl", "#track")
        data = _sub(pm, f"{_K}ExtendedData")
        fields = {
            "track_id": str(track.id),
            "class": track.cls,
            "sensors": ",".join(sorted(track.sensors)),
            "t_start_s": repr(t[0]),
            "t_end_s": repr(t[-1]),
            "n_points": str(len(t)),
            "gaps": json.dumps([[a, b] for a, b in track.gaps]),
            "epoch_utc": times.epoch_iso,
            "wall_clock": "yes" if times.wall_clock else "no",
            "altitude": (
                f"orthometric, above the {heights.datum_name}"
                if heights.orthometric
                else "ellipsoidal (no geoid model)"
            ),
        }
        for key, value in fields.items():
            _sub(_sub(data, f"{_K}Data", name=key), f"{_K}value", value)
        multi = _sub(pm, f"{_G}MultiTrack")
        _sub(multi, f"{_K}altitudeMode", "absolute")
        _sub(multi, f"{_G}interpolate", "0")
        for run in xt.runs:
            gxt = _sub(multi, f"{_G}Track")
            _sub(gxt, f"{_K}altitudeMode", "absolute")
            for i in run:
                _sub(gxt, f"{_K}when", xt.times_utc[i])
            for i in run:
                lon, lat, alt = (float(v[i]) for v in (xt.lon_deg, xt.lat_deg, xt.abs_h_m))
                _sub(gxt, f"{_G}coord", f"{lon!r} {lat!r} {alt!r}")
    tree = ET.ElementTree(root)
    ET.indent(tree)
    buf = io.StringIO()
    buf.write('<?xml version="1.0" encoding="UTF-8"?>\n')
    tree.write(buf, encoding="unicode")
    buf.write("\n")
    return buf.getvalue()


def kmz_bytes(kml: str) -> bytes:
    """A KMZ archive holding ``kml`` as ``doc.kml`` (deflated, fixed date)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        info = zipfile.ZipInfo("doc.kml", date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        zf.writestr(info, kml.encode("utf-8"))
    return buf.getvalue()
