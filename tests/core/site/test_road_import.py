"""Road lines in any CRS: GeoJSON (RFC 7946, legacy "crs" member, explicit CRS) and
GeoPackage geometry blobs (header + WKB) read with sqlite3 and shapely."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import shapely
from pyproj import Transformer

from demtrack.core.errors import CrsError, InputFileError
from demtrack.core.site.road_io import gpkg_geometry_wkb, read_road_lines

XY = np.array([[589_000.0, 4_467_000.0], [589_250.5, 4_467_120.25], [589_400.0, 4_467_500.0]])
LON, LAT = Transformer.from_crs("EPSG:32617", "EPSG:4326", always_xy=True).transform(
    XY[:, 0], XY[:, 1]
)


def _fc(coords, crs=None):
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"name": "main", "width_m": 8.5},
                "geometry": {"type": "LineString", "coordinates": coords},
            }
        ],
    }
    if crs:
        doc["crs"] = {"type": "name", "properties": {"name": crs}}
    return json.dumps(doc)


def test_geojson_in_utm_by_member_or_option_and_wgs84_default(tmp_path):
    (tmp_path / "a.geojson").write_text(_fc(XY.tolist(), "urn:ogc:def:crs:EPSG::32617"))
    (tmp_path / "b.geojson").write_text(_fc(XY.tolist()))
    (tmp_path / "c.geojson").write_text(_fc(np.column_stack([LON, LAT]).tolist()))
    for lines in (
        read_road_lines(tmp_path / "a.geojson"),
        read_road_lines(tmp_path / "b.geojson", crs="EPSG:32617"),
        read_road_lines(tmp_path / "c.geojson"),
    ):
        np.testing.assert_allclose(lines.lonlat[0], np.column_stack([LON, LAT]), atol=1e-10)
        assert lines.names == ("main",) and lines.widths_m == (8.5,)
    # UTM numbers read as lon/lat are not valid coordinates.
    with pytest.raises(CrsError, match="not valid"):
        read_road_lines(tmp_path / "b.geojson")


@pytest.mark.parametrize(
    ("env_code", "env_len", "order"), [(0, 0, "<"), (1, 32, ">"), (2, 48, "<"), (4, 64, "<")]
)
def test_gpkg_blob_header_is_skipped(env_code, env_len, order):
    geom = shapely.LineString(XY)
    flags = (env_code << 1) | (1 if order == "<" else 0)
    blob = b"GP" + bytes([0, flags]) + struct.pack(order + "i", 32617) + b"\0" * env_len
    blob += shapely.to_wkb(geom)
    wkb, srs = gpkg_geometry_wkb(blob)
    assert srs == 32617
    assert shapely.from_wkb(wkb).equals(geom)
    with pytest.raises(InputFileError, match="no 'GP' magic"):
        gpkg_geometry_wkb(b"XX" + blob[2:])


def test_not_a_geopackage(tmp_path):
    (tmp_path / "r.gpkg").write_bytes(b"SQLite format 3\0" + b"\0" * 100)
    with pytest.raises(InputFileError):
        read_road_lines(tmp_path / "r.gpkg")
