"""Road networks as GeoJSON (RFC 7946: WGS84 longitude/latitude), and road import.

A site's road file is a FeatureCollection of LineString (or MultiLineString) features;
the optional properties ``name`` and ``width_m`` are kept. Coordinates are converted to
the site frame through the site's :class:`~demtrack.core.geo.geodesy.LocalFrame`; heights in
the file, if any, are ignored (a road lies on the DEM): positions are read and written at
the anchor's height, local up = 0.

Import (:func:`read_road_lines`): GeoJSON in any CRS (RFC 7946 WGS84 by default; the
legacy ``"crs"`` member or an explicit CRS overrides it) or a GeoPackage line layer (its
CRS from ``gpkg_spatial_ref_sys``), converted to WGS84 lon/lat for the site's file.
A GeoPackage geometry blob is a header (``GP``, version, flags, srs_id, an optional
envelope whose size the flags give) followed by ISO WKB, read here with sqlite3 and
shapely, no GDAL vector driver needed.
"""

from __future__ import annotations

import json
import sqlite3
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CrsError, DemtrackError, InputFileError
from ..geo.geodesy import LocalFrame, cached_transformer, horizontal_crs
from ..geolocation.roads import RoadNetwork
from ..io.geojson_io import read_features

__all__ = [
    "RoadLines",
    "gpkg_geometry_wkb",
    "read_road_lines",
    "read_roads_geojson",
    "road_lines_to_geojson",
    "roads_to_geojson",
    "write_roads_geojson",
]


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


# --------------------------------------------------------------------------- import


@dataclass(frozen=True, eq=False)
class RoadLines:
    """Road centre lines in WGS84.

    Attributes
    ----------
    lonlat : tuple of ndarray, each shape (k >= 2, 2)
        Longitude, latitude (degrees), GeoJSON order.
    names : tuple of str
    widths_m : tuple of float
    """

    lonlat: tuple[np.ndarray, ...]
    names: tuple[str, ...]
    widths_m: tuple[float, ...]


_ENVELOPE_BYTES = {0: 0, 1: 32, 2: 48, 3: 48, 4: 64}


def gpkg_geometry_wkb(blob: bytes) -> tuple[bytes, int]:
    """Split a GeoPackage geometry blob into its WKB and its ``srs_id``.

    Raises
    ------
    InputFileError
        If the blob is not a GeoPackage geometry (bad magic, version or envelope code).
    """
    if len(blob) < 8 or blob[:2] != b"GP":
        raise InputFileError("not a GeoPackage geometry blob (no 'GP' magic)")
    flags = blob[3]
    if flags & 0b00100000:
        raise InputFileError("extended GeoPackage geometry types are not supported")
    env = (flags >> 1) & 0b111
    if env not in _ENVELOPE_BYTES:
        raise InputFileError(f"GeoPackage geometry has an invalid envelope code {env}")
    srs_id = struct.unpack("<i" if flags & 1 else ">i", blob[4:8])[0]
    return bytes(blob[8 + _ENVELOPE_BYTES[env] :]), srs_id


def _gpkg_lines(path: Path, layer: str | None) -> tuple[list[tuple[Any, dict[str, Any]]], str]:
    import shapely.wkb

    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    except sqlite3.Error as exc:
        raise InputFileError(f"cannot open GeoPackage {path}: {exc}") from None
    try:
        try:
            layers = con.execute(
                "SELECT table_name, column_name, srs_id FROM gpkg_geometry_columns"
            ).fetchall()
        except sqlite3.DatabaseError:
            raise InputFileError(f"{path} is not a GeoPackage (no gpkg_geometry_columns)") from None
        if layer is not None:
            layers = [row for row in layers if row[0] == layer]
            if not layers:
                raise InputFileError(f"GeoPackage {path} has no layer {layer!r}")
        if len(layers) != 1:
            names = ", ".join(row[0] for row in layers) or "none"
            raise InputFileError(
                f"GeoPackage {path} has {len(layers)} geometry layers ({names}); pick one "
                "with --layer"
            )
        table, column, srs_id = layers[0]
        srs = con.execute(
            "SELECT organization, organization_coordsys_id, definition FROM "
            "gpkg_spatial_ref_sys WHERE srs_id = ?",
            (srs_id,),
        ).fetchone()
        if srs is None or srs_id in (0, -1):
            raise CrsError(f"GeoPackage layer {table!r} has no usable CRS (srs_id {srs_id})")
        org, code, definition = srs
        crs_text = f"{org}:{code}" if org and str(org).upper() == "EPSG" else definition
        cur = con.execute(f'SELECT * FROM "{table}"')  # noqa: S608 - name from the file's catalogue
        cols = [d[0] for d in cur.description]
        out = []
        for row in cur:
            rec = dict(zip(cols, row, strict=True))
            blob = rec.pop(column)
            if blob is None:
                continue
            wkb, _ = gpkg_geometry_wkb(blob)
            try:
                geom = shapely.wkb.loads(wkb)
            except Exception as exc:  # noqa: BLE001 - shapely raises GEOS errors
                raise InputFileError(f"GeoPackage {path}: bad geometry: {exc}") from None
            out.append((geom, rec))
    except sqlite3.DatabaseError as exc:
        raise InputFileError(f"cannot read GeoPackage {path}: {exc}") from None
    finally:
        con.close()
    return out, crs_text


def _parts(geom: Any, k: int) -> list[np.ndarray]:
    kind = geom.geom_type
    if kind == "LineString":
        return [np.asarray(geom.coords, dtype=np.float64)]
    if kind == "MultiLineString":
        return [np.asarray(g.coords, dtype=np.float64) for g in geom.geoms]
    raise InputFileError(f"road feature {k}: geometry must be a LineString, got {kind!r}")


def read_road_lines(path: str | Path, *, crs: Any = None, layer: str | None = None) -> RoadLines:
    """Read road centre lines from GeoJSON or GeoPackage in any CRS, as WGS84 lon/lat.

    Parameters
    ----------
    path : path
        ``.geojson``/``.json`` or ``.gpkg``.
    crs : CRS-like, optional
        CRS of the coordinates, overriding the file's (GeoJSON's default is WGS84
        lon/lat per RFC 7946, or its legacy ``"crs"`` member; a GeoPackage states its own).
    layer : str, optional
        GeoPackage layer (required when it has several).

    Raises
    ------
    InputFileError, CrsError
        On unreadable files, non-line geometries, or an unknown CRS.
    """
    from shapely.geometry import shape

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"road file not found: {path}")
    if path.suffix.lower() == ".gpkg":
        records, file_crs = _gpkg_lines(path, layer)
        props = [r for _, r in records]
        geoms = [g for g, _ in records]
    else:
        features = read_features(path, "road")
        try:
            doc_crs = json.loads(path.read_text(encoding="utf-8")).get("crs")
        except (OSError, ValueError, AttributeError):
            doc_crs = None
        file_crs = "OGC:CRS84"
        if isinstance(doc_crs, dict):
            name = (doc_crs.get("properties") or {}).get("name")
            if name:
                file_crs = str(name)
        geoms, props = [], []
        for k, f in enumerate(features):
            try:
                geoms.append(shape(f.get("geometry") or {}))
            except (AttributeError, KeyError, TypeError, ValueError, IndexError):
                raise InputFileError(f"road feature {k}: malformed geometry") from None
            props.append(f.get("properties") or {})
    try:
        hcrs = horizontal_crs(crs if crs is not None else file_crs)
    except DemtrackError as exc:
        raise CrsError(f"road file {path}: {exc}") from None
    to_ll = cached_transformer(hcrs.to_wkt(), "EPSG:4326")
    lonlat: list[np.ndarray] = []
    names: list[str] = []
    widths: list[float] = []
    for k, (geom, prop) in enumerate(zip(geoms, props, strict=True)):
        for xy in _parts(geom, k):
            if len(xy) < 2 or not np.isfinite(xy[:, :2]).all():
                raise InputFileError(f"road feature {k}: needs at least two finite positions")
            lon, lat = to_ll.transform(xy[:, 0], xy[:, 1])
            ll = np.column_stack([lon, lat])
            if not np.isfinite(ll).all() or np.abs(ll[:, 1]).max() > 90.0:
                raise CrsError(f"road feature {k}: coordinates are not valid in {hcrs.name!r}")
            lonlat.append(ll)
            names.append(str(prop.get("name") or f"road {len(names)}"))
            width = prop.get("width_m", 6.0)
            widths.append(float(width) if isinstance(width, int | float) else 6.0)
    if not lonlat:
        raise InputFileError(f"road file {path} has no line features")
    return RoadLines(tuple(lonlat), tuple(names), tuple(widths))


def road_lines_to_geojson(lines: RoadLines) -> dict:
    """RFC 7946 FeatureCollection (lon/lat, WGS84) of imported road lines."""
    return {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"name": name, "width_m": width},
                "geometry": {
                    "type": "LineString",
                    "coordinates": [[round(float(a), 9), round(float(b), 9)] for a, b in ll],
                },
            }
            for ll, name, width in zip(lines.lonlat, lines.names, lines.widths_m, strict=True)
        ],
    }
