"""Zones drawn on the map as GeoJSON polygons (RFC 7946 lon/lat) -> site-frame polygons."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely

from ..activity.zones import Zone
from ..errors import InputFileError
from ..geo.geodesy import LocalFrame
from ..io.geojson_io import read_features

__all__ = ["read_zones_geojson"]


def _ring_enu(ring: list, frame: LocalFrame, k: int) -> np.ndarray:
    try:
        lonlat = np.asarray(ring, dtype=np.float64)[:, :2]
    except (TypeError, ValueError, IndexError):
        raise InputFileError(f"zone feature {k}: malformed coordinates") from None
    if len(lonlat) < 4 or not np.isfinite(lonlat).all():
        raise InputFileError(f"zone feature {k}: a ring needs at least 4 finite positions")
    # Positions at the anchor's height, as roads are (local up 0).
    e, n, _ = frame.to_enu(lonlat[:, 1], lonlat[:, 0], np.full(len(lonlat), frame.h_m))
    return np.column_stack([e, n])


def read_zones_geojson(path: str | Path, frame: LocalFrame) -> list[Zone]:
    """Read Polygon / MultiPolygon features; ``properties.name`` names each zone.

    Raises
    ------
    InputFileError
        Missing file, bad JSON, not a FeatureCollection, or a feature that is not a valid
        polygon.
    """
    features = read_features(path, "zone")
    zones = []
    for k, feature in enumerate(features):
        geom = (feature or {}).get("geometry") or {}
        name = str(((feature or {}).get("properties") or {}).get("name", f"zone {k + 1}"))
        if geom.get("type") == "Polygon":
            polys = [geom.get("coordinates") or []]
        elif geom.get("type") == "MultiPolygon":
            polys = list(geom.get("coordinates") or [])
        else:
            raise InputFileError(f"zone feature {k}: geometry must be a Polygon")
        parts = []
        for rings in polys:
            if not rings:
                raise InputFileError(f"zone feature {k}: empty polygon")
            shell, holes = (
                _ring_enu(rings[0], frame, k),
                [_ring_enu(r, frame, k) for r in rings[1:]],
            )
            parts.append(shapely.Polygon(shell, holes))
        poly = parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)
        if not poly.is_valid:
            raise InputFileError(f"zone feature {k} ({name}): {shapely.is_valid_reason(poly)}")
        zones.append(Zone(name, poly))
    return zones
