import csv
import io
import json
from datetime import UTC, datetime, timedelta, timezone
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from demtrack.core.errors import TrackingError
from demtrack.core.io.track_io import (
    GPX_NS,
    TRACK_CSV_COLUMNS,
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


def test_geojson_round_trip(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.geojson"
    write_tracks_geojson(path, tracks, to_geodetic, include_points=True, epoch=EPOCH)
    doc = json.loads(path.read_text())
    assert doc["type"] == "FeatureCollection"
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds.count("track") == 2 and kinds.count("point") == 6
    car = doc["features"][0]
    assert car["geometry"]["type"] == "LineString"
    for coord, p in zip(car["geometry"]["coordinates"], tracks[0].points, strict=True):
        lat, lon, h = to_geodetic(*p.p_enu)
        assert coord == [lon, lat, h]  # RFC 7946 order: lon, lat, height
    props = car["properties"]
    assert props["track_id"] == 3 and props["class"] == "vehicle"
    assert props["sensors"] == ["a", "b"] and props["gaps"] == [[1.0, 4.0]]
    assert props["times_s"] == [0.0, 0.5, 1.0, 4.0, 4.5]
    assert props["enu"][1] == [5.0, -1.5, 0.25]
    assert props["times_utc"][1] == "2024-05-01T12:00:00.500Z"
    person = next(
        f
        for f in doc["features"]
        if f["properties"]["track_id"] == 7 and f["properties"]["kind"] == "track"
    )
    assert person["geometry"]["type"] == "Point"
    pt = next(f for f in doc["features"] if f["properties"]["kind"] == "point")
    assert pt["properties"]["fix_indices"] == [0, 100]
    assert "times_utc" not in tracks_to_geojson(tracks, to_geodetic)["features"][0]["properties"]


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
        assert (float(row["lat_deg"]), float(row["lon_deg"]), float(row["h_m"])) == to_geodetic(
            *p.p_enu
        )
        assert row["sensors"].split(";") == list(p.sensors)
        assert [int(i) for i in row["fix_indices"].split(";")] == list(p.fix_indices)
    assert rows[0]["cov_ee_m2"] == "" and float(rows[1]["cov_nn_m2"]) == 0.2
    assert rows[3]["time_utc"] == "2024-05-01T12:00:04.000Z"
    bare = io.StringIO()
    write_tracks_csv(bare, tracks)
    row = next(csv.DictReader(io.StringIO(bare.getvalue())))
    assert row["lat_deg"] == "" and row["time_utc"] == ""


def test_gpx_round_trip(tmp_path):
    tracks = _tracks()
    path = tmp_path / "t.gpx"
    write_tracks_gpx(path, tracks, to_geodetic, epoch=EPOCH)
    root = ET.parse(path).getroot()
    ns = {"g": GPX_NS}
    assert root.tag == f"{{{GPX_NS}}}gpx" and root.get("version") == "1.1"
    trks = root.findall("g:trk", ns)
    assert [t.find("g:name", ns).text for t in trks] == ["track 3", "track 7"]
    assert trks[0].find("g:type", ns).text == "vehicle"
    segs = trks[0].findall("g:trkseg", ns)
    assert [len(s.findall("g:trkpt", ns)) for s in segs] == [3, 2]  # split at the gap
    pts = [p for s in segs for p in s.findall("g:trkpt", ns)]
    for el, p in zip(pts, tracks[0].points, strict=True):
        lat, lon, h = to_geodetic(*p.p_enu)
        assert float(el.get("lat")) == lat and float(el.get("lon")) == lon
        assert float(el.find("g:ele", ns).text) == h
        when = datetime.strptime(el.find("g:time", ns).text, "%Y-%m-%dT%H:%M:%S.%fZ")
        assert when.replace(tzinfo=UTC) == EPOCH + timedelta(seconds=p.t_s)
    with pytest.raises(TrackingError, match="timezone"):
        write_tracks_gpx(io.StringIO(), tracks, to_geodetic, epoch=datetime(2024, 1, 1))


def test_iso_utc_and_gap_runs():
    plus2 = timezone(timedelta(hours=2))
    assert iso_utc(datetime(2024, 1, 1, 2, 0, tzinfo=plus2), 61.25) == "2024-01-01T00:01:01.250Z"
    car = _tracks()[0]
    assert split_at_gaps(car) == [[0, 1, 2], [3, 4]]
    assert split_at_gaps(Track(1, "human", car.points)) == [[0, 1, 2, 3, 4]]
