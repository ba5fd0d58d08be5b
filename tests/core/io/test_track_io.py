"""GeoJSON, CSV and GPX track writers; GPX read back by gpxpy, the CSV by :mod:`csv`."""

from __future__ import annotations

import csv
import io
import json
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import gpxpy
import numpy as np
import pytest

from demtrack.core.errors import TrackingError
from demtrack.core.io.track_io import (
    TRACK_CSV_COLUMNS,
    HeightModel,
    TimeBase,
    iso_utc,
    split_at_gaps,
    tracks_to_geojson,
    write_tracks_csv,
    write_tracks_geojson,
    write_tracks_gpx,
)
from demtrack.core.tracking.types import Track, TrackPoint

EPOCH = datetime(2024, 5, 1, 12, 0, 0, tzinfo=UTC)


def to_geodetic(e, n, u):
    """A stand-in converter (not geodesy): linear in each coordinate."""
    return 45.0 + n / 111_000.0, 7.0 + e / 78_000.0, 100.0 + u


def _tracks():
    t = [0.0, 0.5, 1.0, 4.0, 4.5]
    pts = [
        TrackPoint(
            ti,
            [10.0 * ti, -3.0 * ti, 0.25 * k],
            ("a",) if k % 2 else ("a", "b"),
            (k,) if k % 2 else (k, k + 100),
            np.diag([0.1, 0.2]) if k else None,
        )
        for k, ti in enumerate(t)
    ]
    car = Track(3, "vehicle", pts, {"a", "b"}, [(1.0, 4.0)])
    person = Track(7, "human", [TrackPoint(2.0, [1.0, 2.0, 3.0], ("b",), (9,))], {"b"})
    return [car, person]


def _lonlath(p):
    lat, lon, h = to_geodetic(*p.p_enu)
    return [lon, lat, h]


def test_geojson_round_trip(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.geojson"
    write_tracks_geojson(path, tracks, to_geodetic, include_points=True, epoch=EPOCH)
    doc = json.loads(path.read_text())
    assert doc["type"] == "FeatureCollection"
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds.count("track") == 2 and kinds.count("point") == 6
    car = doc["features"][0]
    # The gap (1 s .. 4 s) is not a line: one line per run, RFC 7946 order lon, lat, h.
    assert car["geometry"]["type"] == "MultiLineString"
    pts = tracks[0].points
    assert car["geometry"]["coordinates"] == [
        [_lonlath(p) for p in pts[:3]],
        [_lonlath(p) for p in pts[3:]],
    ]
    props = car["properties"]
    assert props["track_id"] == 3 and props["class"] == "vehicle"
    assert props["sensors"] == ["a", "b"] and props["gaps"] == [[1.0, 4.0]]
    assert props["times_s"] == [0.0, 0.5, 1.0, 4.0, 4.5] and props["n_segments"] == 2
    assert props["enu"][1] == [5.0, -1.5, 0.25]
    assert props["times_utc"][1] == "2024-05-01T12:00:00.500Z"
    assert props["epoch_utc"] == "2024-05-01T12:00:00.000Z" and props["wall_clock"] is False
    assert "no geoid model" in props["height"] and "elevation_m" not in props
    person = next(
        f
        for f in doc["features"]
        if f["properties"]["track_id"] == 7 and f["properties"]["kind"] == "track"
    )
    # One point: a zero-length line, so every track feature has the same geometry type.
    assert person["geometry"] == {
        "type": "MultiLineString",
        "coordinates": [[_lonlath(tracks[1].points[0])] * 2],
    }
    pt = next(f for f in doc["features"] if f["properties"]["kind"] == "point")
    assert pt["properties"]["fix_indices"] == [0, 100]
    # Without an epoch the times are declared relative to the UNIX epoch.
    bare = tracks_to_geojson(tracks, to_geodetic)["features"][0]["properties"]
    assert bare["times_utc"][3] == "1970-01-01T00:00:04.000Z"
    assert "1970-01-01T00:00:00.000Z" in bare["time"] and "session seconds" in bare["time"]


def test_csv_round_trip():
    tracks = _tracks()
    buf = io.StringIO()
    write_tracks_csv(buf, tracks, to_geodetic, epoch=EPOCH)
    rows = list(csv.DictReader(io.StringIO(buf.getvalue())))
    assert tuple(rows[0]) == TRACK_CSV_COLUMNS
    assert len(rows) == 6
    for row, p in zip(rows[:5], tracks[0].points, strict=True):
        assert row["track_id"] == "3" and row["class"] == "vehicle"
        assert float(row["t_s"]) == p.t_s
        assert [float(row[c]) for c in ("e_m", "n_m", "u_m")] == list(p.p_enu)
        lon, lat, h = _lonlath(p)
        assert (float(row["longitude"]), float(row["latitude"]), float(row["h_wgs84_m"])) == (
            lon,
            lat,
            h,
        )
        assert row["elevation_m"] == ""  # no geoid model given
        assert row["sensors"].split(";") == list(p.sensors)
        assert [int(i) for i in row["fix_indices"].split(";")] == list(p.fix_indices)
    assert [r["segment"] for r in rows] == ["0", "0", "0", "1", "1", "0"]
    assert rows[0]["cov_ee_m2"] == "" and float(rows[1]["cov_nn_m2"]) == 0.2
    assert rows[3]["time_utc"] == "2024-05-01T12:00:04.000Z"
    bare = io.StringIO()
    write_tracks_csv(bare, tracks)
    row = next(csv.DictReader(io.StringIO(bare.getvalue())))
    assert row["latitude"] == "" and row["time_utc"] == "1970-01-01T00:00:00.000Z"


def test_gpx_read_back_by_gpxpy(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpx"
    write_tracks_gpx(path, tracks, to_geodetic, epoch=EPOCH)
    gpx = gpxpy.parse(path.read_text())
    assert gpx.version == "1.1"
    assert [t.name for t in gpx.tracks] == ["track 3", "track 7"]
    assert gpx.tracks[0].type == "vehicle"
    segs = gpx.tracks[0].segments
    assert [len(s.points) for s in segs] == [3, 2]  # split at the gap
    pts = [p for s in segs for p in s.points]
    for got, p in zip(pts, tracks[0].points, strict=True):
        lon, lat, h = _lonlath(p)
        assert (got.latitude, got.longitude, got.elevation) == (lat, lon, h)
        assert got.time == EPOCH + timedelta(seconds=p.t_s)  # UTC, tz-aware
        assert got.time.utcoffset() == timedelta(0)
    assert "ellipsoid" in gpx.description and "2024-05-01T12:00:00.000Z" in gpx.description
    with pytest.raises(TrackingError, match="timezone"):
        write_tracks_gpx(io.StringIO(), tracks, to_geodetic, epoch=datetime(2024, 1, 1))
    # The raw text: every point has <time> with Z and <ele>.
    text = path.read_text()
    assert text.count("<time>") == 1 + 6 and text.count("<ele>") == 6
    assert "Z</time>" in text and "+00:00" not in text


def test_heights_follow_the_geoid_model(tmp_path):
    tracks = _tracks()
    n_m = -33.5
    heights = HeightModel.constant_undulation(n_m)
    buf = io.StringIO()
    write_tracks_csv(buf, tracks, to_geodetic, heights=heights)
    rows = list(csv.DictReader(io.StringIO(buf.getvalue())))
    for row in rows:
        assert float(row["elevation_m"]) == pytest.approx(float(row["h_wgs84_m"]) - n_m)
    path = tmp_path / "t.gpx"
    write_tracks_gpx(path, tracks, to_geodetic, heights=heights)
    gpx = gpxpy.parse(path.read_text())
    eles = [p.elevation for t in gpx.tracks for s in t.segments for p in s.points]
    want = [_lonlath(p)[2] - n_m for t in tracks for p in t.points]
    assert eles == pytest.approx(want, abs=1e-9)
    assert "orthometric" in gpx.description and "-33.5" in gpx.description
    # A per-point model (as EGM96 will be) is called with the arrays.
    seen = []

    def geoid(lat, lon, h):
        seen.append(len(lat))
        return h - lat  # a stand-in N(lat, lon) = lat

    doc = tracks_to_geojson(tracks, to_geodetic, heights=HeightModel("stand-in", geoid))
    car = doc["features"][0]["properties"]
    assert seen == [5, 1]
    assert car["elevation_m"] == [_lonlath(p)[2] - _lonlath(p)[1] for p in tracks[0].points]
    with pytest.raises(TrackingError, match="both"):
        HeightModel("EGM96")


def test_time_base_declares_its_epoch():
    tb = TimeBase(EPOCH, wall_clock=True)
    assert tb.iso(1.2346) == "2024-05-01T12:00:01.235Z" and "UTC" in tb.note
    assert "declared epoch" in TimeBase(EPOCH).note
    with pytest.raises(TrackingError, match="timezone"):
        TimeBase(datetime(2024, 1, 1))


def test_iso_utc_and_gap_runs():
    plus2 = timezone(timedelta(hours=2))
    assert iso_utc(datetime(2024, 1, 1, 2, 0, tzinfo=plus2), 61.25) == "2024-01-01T00:01:01.250Z"
    car = _tracks()[0]
    assert split_at_gaps(car) == [[0, 1, 2], [3, 4]]
    assert split_at_gaps(Track(1, "human", car.points)) == [[0, 1, 2, 3, 4]]


def test_geoid_grid_model_has_the_sign_of_h_minus_n(tmp_path):
    # EGM96 puts the geoid about 34 m below the ellipsoid at Bushy Run (N ~ -33.9 m, as
    # NGA's EGM96 calculator gives), so sea-level heights there are about 34 m above h.
    grid = Path("/usr/share/proj/egm96_15.gtx")
    with pytest.raises(TrackingError, match="does not exist"):
        HeightModel.geoid_grid(tmp_path / "none.gtx")
    if not grid.is_file():
        pytest.skip("needs Debian's proj-data (egm96_15.gtx)")
    hm = HeightModel.geoid_grid(grid)
    big_h = hm.absolute(np.array([40.35]), np.array([-79.6]), np.array([300.0]))
    assert big_h[0] - 300.0 == pytest.approx(33.9, abs=0.5)
    assert "egm96_15" in hm.note and hm.orthometric
