"""Road networks as GeoJSON (RFC 7946: WGS84 longitude/latitude).

A road file is a FeatureCollection of LineString (or MultiLineString) features; the
optional properties ``name`` and ``width_m`` are kept. Coordinates are converted to the
site frame through the site's :class:`~demtrack.core.geodesy.LocalFrame`; heights in the
file, if any, are ignored (a road lies on the DEM): positions are read and written at
the anchor's height, local up = 0.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputFileError
from .geodesy import LocalFrame
from .geojson_io import read_features
from .roads import RoadNetwork

__all__ = ["read_roads_geojson", "roads_to_geojson", "write_roads_geojson"]


def _lines_of(feature: dict[str, Any], k: int) -> list[Any]:
    geom = feature.get("geometry") or {}
    kind = geom.get("type")
    coords = geom.get("coordinates")
    if kind == "LineString" and coords is not None:
        return [coords]
    if kind == "MultiLineString" and isinstance(coords, list):
        return list(coords)
    raise InputFileError(f"road feature {k}: geometry must be a LineString, got {kind!r}")


def read_roads_geojson(path: str | Path, frame: LocalFrame) -> RoadNetwork:
    """Read a road GeoJSON file into a :class:`RoadNetwork` in the site frame.

    Raises
    ------
    InputFileError
        If the file is missing, not JSON, not a FeatureCollection, or a feature is not a
        line with at least two finite lon/lat positions.
    """
    features = read_features(path, "road")
    coords: list[np.ndarray] = []
    names: list[str] = []
    widths: list[float] = []
    for k, feature in enumerate(features):
        props = feature.get("properties") or {}
        for part in _lines_of(feature, k):
            try:
                lonlat = np.asarray(part, dtype=np.float64)[:, :2]
            except (TypeError, ValueError, IndexError):
                raise InputFileError(f"road feature {k}: malformed coordinates") from None
            if lonlat.ndim != 2 or len(lonlat) < 2 or not np.isfinite(lonlat).all():
                raise InputFileError(f"road feature {k}: needs at least two finite positions")
            # 2-D positions: place them at the anchor's height (local up 0), the height
            # the writer uses; a vertical offset dz moves e/n by dz * d / R (< 1 mm here).
            h = np.full(len(lonlat), frame.h_m)
            e, n, _ = frame.to_enu(lonlat[:, 1], lonlat[:, 0], h)
            coords.append(np.column_stack([e, n]))
            names.append(str(props.get("name", f"road {len(names)}")))
            widths.append(float(props.get("width_m", 6.0)))
    if not coords:
        raise InputFileError(f"road file {path} has no line features")
    return RoadNetwork.from_coordinates(coords, names, widths)


def roads_to_geojson(roads: RoadNetwork, frame: LocalFrame, ground_h_m: float = 0.0) -> dict:
    """GeoJSON FeatureCollection (lon/lat) of a road network in the site frame.

    ``ground_h_m`` is the local-frame height used for the conversion; horizontal positions
    depend on it by well under a millimetre over a site.
    """
    features = []
    for line, name, width in zip(roads.lines, roads.names, roads.widths_m, strict=True):
        xy = np.asarray(line.coords, dtype=np.float64)
        lat, lon, _ = frame.to_geodetic(xy[:, 0], xy[:, 1], np.full(len(xy), ground_h_m))
        features.append(
            {
                "type": "Feature",
                "properties": {"name": name, "width_m": width},
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [round(float(a), 9), round(float(b), 9)]
                        for a, b in zip(lon, lat, strict=True)
                    ],
                },
            }
        )
    return {"type": "FeatureCollection", "features": features}


def write_roads_geojson(
    path: str | Path, roads: RoadNetwork, frame: LocalFrame, ground_h_m: float = 0.0
) -> None:
    """Write :func:`roads_to_geojson` to ``path``."""
    Path(path).write_text(json.dumps(roads_to_geojson(roads, frame, ground_h_m)), "utf-8")
