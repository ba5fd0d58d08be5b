"""Both heights leave with their names: CSV and GeoJSON columns through a site's GeoidModel."""

from __future__ import annotations

import csv
import io

import numpy as np
import pyogrio.raw
import pytest
from geoid_oracle import write_linear_tif

from demtrack.core.geo.geoid import GeoidModel
from demtrack.core.io.track_io import (
    TRACK_CSV_COLUMNS,
    TRACK_CSVT,
    HeightModel,
    tracks_to_geojson,
    write_tracks_csv,
)
from demtrack.core.tracking.types import Track, TrackPoint


def to_geodetic(e, n, u):
    return 40.4 + n / 111_000.0, -79.7 + e / 85_000.0, 300.0 + u


def _tracks():
    pts = [TrackPoint(float(k), [400.0 * k, 300.0 * k, 1.0], ("a",), (k,)) for k in range(8)]
    return [Track(1, "vehicle", pts, {"a"})]


@pytest.fixture
def national(tmp_path):
    grid = tmp_path / "national.tif"
    write_linear_tif(grid, -30.0 + 40.0 * 79.6225, 40.0, 0.0)  # N = -30 + 40 (lon + 79.6225)
    return GeoidModel.from_grid(grid, "NAT18")


def test_csv_has_ellipsoidal_and_orthometric_columns_named(national, tmp_path):
    assert TRACK_CSV_COLUMNS.index("elevation_datum") == TRACK_CSV_COLUMNS.index("elevation_m") + 1
    assert TRACK_CSVT.count(",") == len(TRACK_CSV_COLUMNS) - 1
    path = tmp_path / "t.csv"
    write_tracks_csv(path, _tracks(), to_geodetic, heights=HeightModel.from_geoid(national))
    path.with_suffix(".csvt").write_text(TRACK_CSVT)
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    lon = np.array([float(r["longitude"]) for r in rows])
    h = np.array([float(r["h_wgs84_m"]) for r in rows])
    big_h = np.array([float(r["elevation_m"]) for r in rows])
    # The grid's N varies along the track (1.3 m over it): evaluated at each point.
    np.testing.assert_allclose(big_h, h - (-30.0 + 40.0 * (lon + 79.6225)), atol=1e-4)
    assert np.ptp(h - big_h) > 1.0
    assert {r["elevation_datum"] for r in rows} == {"NAT18 geoid"}
    # GDAL reads the types from the .csvt: the datum is a string, the heights reals.
    meta, _, _, fields = pyogrio.raw.read(
        path, X_POSSIBLE_NAMES="longitude", Y_POSSIBLE_NAMES="latitude"
    )
    cols = dict(zip(meta["fields"], fields, strict=True))
    assert list(cols["elevation_datum"]) == ["NAT18 geoid"] * len(rows)
    assert cols["elevation_m"].dtype.kind == "f"
    np.testing.assert_allclose(cols["elevation_m"], big_h)


def test_geojson_keeps_z_ellipsoidal_and_names_both(national):
    doc = tracks_to_geojson(
        _tracks(), to_geodetic, include_points=True, heights=HeightModel.from_geoid(national)
    )
    line, *points = doc["features"]
    z = [c[2] for c in line["geometry"]["coordinates"][0]]
    assert line["properties"]["h_wgs84_m"] == z  # RFC 7946: z is ellipsoidal
    assert line["properties"]["elevation_datum"] == "NAT18 geoid"
    assert "WGS84 ellipsoid" in line["properties"]["height"]
    for p in points:
        lon, lat, h = p["geometry"]["coordinates"]
        assert p["properties"]["h_wgs84_m"] == h
        n = float(national.undulation_m(lat, lon))
        assert p["properties"]["elevation_m"] == pytest.approx(h - n, abs=1e-9)
    # No geoid: no orthometric column claims one.
    plain = tracks_to_geojson(_tracks(), to_geodetic, heights=HeightModel.from_geoid(
        GeoidModel.ellipsoidal()))  # fmt: skip
    assert "elevation_datum" not in plain["features"][0]["properties"]
