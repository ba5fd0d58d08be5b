from __future__ import annotations

import json

import numpy as np
import pytest

from demtrack.core.errors import InputFileError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.site.zone_io import read_zones_geojson

FRAME = LocalFrame(40.3556, -79.6225, 331.0)


def lonlat_ring(xy):
    lat, lon, _ = FRAME.to_geodetic(xy[:, 0], xy[:, 1], np.zeros(len(xy)))
    return [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]


def write(tmp_path, geometry, name="gate"):
    doc = {
        "type": "FeatureCollection",
        "features": [{"type": "Feature", "properties": {"name": name}, "geometry": geometry}],
    }
    (tmp_path / "z.geojson").write_text(json.dumps(doc))
    return tmp_path / "z.geojson"


def test_polygon_with_hole_round_trips_to_the_site_frame(tmp_path):
    shell = np.array([[0, 0], [40, 0], [40, 30], [0, 30], [0, 0]], float)
    hole = np.array([[10, 10], [20, 10], [20, 20], [10, 20], [10, 10]], float)
    path = write(
        tmp_path, {"type": "Polygon", "coordinates": [lonlat_ring(shell), lonlat_ring(hole)]}
    )
    (zone,) = read_zones_geojson(path, FRAME)
    assert zone.name == "gate"
    assert zone.polygon.area == pytest.approx(40 * 30 - 10 * 10, rel=1e-6)


@pytest.mark.parametrize(
    ("geometry", "message"),
    [
        ({"type": "LineString", "coordinates": [[0, 0], [1, 1]]}, "geometry must be a Polygon"),
        ({"type": "Polygon", "coordinates": [[[0, 0], [1, 1]]]}, "at least 4 finite positions"),
        ({"type": "Polygon", "coordinates": []}, "empty polygon"),
    ],
)
def test_bad_zones_are_one_line_errors(tmp_path, geometry, message):
    with pytest.raises(InputFileError, match=message):
        read_zones_geojson(write(tmp_path, geometry), FRAME)


def test_self_intersecting_zone_is_named(tmp_path):
    bow = np.array([[0, 0], [10, 10], [10, 0], [0, 10], [0, 0]], float)
    with pytest.raises(InputFileError, match="zone feature 0 \\(gate\\): Self-intersection"):
        read_zones_geojson(
            write(tmp_path, {"type": "Polygon", "coordinates": [lonlat_ring(bow)]}), FRAME
        )
