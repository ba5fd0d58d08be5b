"""GPX waypoints and KML placemarks of single points (the console's markers).

Heights follow the track exports' rule (:class:`~demtrack.core.io.export_common.HeightModel`):
GPX ``<ele>`` and KML ``absolute`` altitudes are orthometric (metres above the geoid) when
the site has a geoid model, else ellipsoidal, and each document says which. Times are ISO
8601 UTC (:class:`~demtrack.core.io.export_common.TimeBase`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from xml.etree import ElementTree as ET

import gpxpy.gpx
import numpy as np

from .export_common import HeightModel, TimeBase

__all__ = ["Waypoint", "waypoints_gpx", "waypoints_kml"]

_KML_NS = "http://www.opengis.net/kml/2.2"
_K = f"{{{_KML_NS}}}"


@dataclass(frozen=True)
class Waypoint:
    """One point to write: WGS84 position, ellipsoidal height (m), time (UNIX s, UTC)."""

    name: str
    lat_deg: float
    lon_deg: float
    h_m: float
    t_s: float
    description: str = ""


def _absolute(points: Sequence[Waypoint], heights: HeightModel) -> np.ndarray:
    if not points:
        return np.zeros(0)
    lat = np.array([p.lat_deg for p in points], dtype=float)
    lon = np.array([p.lon_deg for p in points], dtype=float)
    h = np.array([p.h_m for p in points], dtype=float)
    return heights.absolute(lat, lon, h)


def waypoints_gpx(
    points: Sequence[Waypoint], heights: HeightModel, times: TimeBase, *, name: str
) -> str:
    """GPX 1.1 with one ``<wpt>`` per point (``<ele>`` = ``heights.absolute``)."""
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "demtrack"
    gpx.name = name
    gpx.description = f"{name}; {heights.note}; {times.note}"
    for p, ele in zip(points, _absolute(points, heights), strict=True):
        gpx.waypoints.append(
            gpxpy.gpx.GPXWaypoint(
                latitude=float(p.lat_deg),
                longitude=float(p.lon_deg),
                elevation=float(ele),
                time=times.datetime(p.t_s),
                name=p.name,
                description=p.description or None,
            )
        )
    return gpx.to_xml(version="1.1") + "\n"


def waypoints_kml(
    points: Sequence[Waypoint], heights: HeightModel, times: TimeBase, *, name: str
) -> str:
    """KML 2.2 with one ``<Placemark>`` per point (``absolute`` = ``heights.absolute``)."""
    ET.register_namespace("", _KML_NS)
    root = ET.Element(f"{_K}kml")
    doc = ET.SubElement(root, f"{_K}Document")
    ET.SubElement(doc, f"{_K}name").text = name
    ET.SubElement(
        doc, f"{_K}description"
    ).text = f"{name}; coordinates are lon,lat,alt; {heights.note}; {times.note}"
    for p, alt in zip(points, _absolute(points, heights), strict=True):
        pm = ET.SubElement(doc, f"{_K}Placemark")
        ET.SubElement(pm, f"{_K}name").text = p.name
        if p.description:
            ET.SubElement(pm, f"{_K}description").text = p.description
        ET.SubElement(ET.SubElement(pm, f"{_K}TimeStamp"), f"{_K}when").text = times.iso(p.t_s)
        pt = ET.SubElement(pm, f"{_K}Point")
        ET.SubElement(pt, f"{_K}altitudeMode").text = "absolute"
        ET.SubElement(
            pt, f"{_K}coordinates"
        ).text = f"{p.lon_deg:.9f},{p.lat_deg:.9f},{float(alt):.3f}"
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
