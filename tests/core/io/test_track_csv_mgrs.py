"""The track CSV's ``mgrs`` column: each point's 1 m reference, read by GDAL as text."""

from __future__ import annotations

import csv
import io

import mgrs
import numpy as np
import pyogrio

from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.io.track_io import TRACK_CSV_COLUMNS, TRACK_CSVT, write_tracks_csv
from demtrack.core.tracking.types import Track, TrackPoint


def _tracks():
    pts = [TrackPoint(float(k), [37.0 * k, -11.0 * k, 0.5], ("a",), (k,)) for k in range(6)]
    return [Track(1, "vehicle", pts, {"a"})]


def test_mgrs_column_is_the_points_reference(tmp_path):
    frame = LocalFrame(40.3581, -79.4703, 300.0)  # Bushy Run, PA: zone 17T
    buf = io.StringIO()
    write_tracks_csv(buf, _tracks(), frame.to_geodetic)
    rows = list(csv.DictReader(io.StringIO(buf.getvalue())))
    assert TRACK_CSV_COLUMNS.index("mgrs") == TRACK_CSV_COLUMNS.index("elevation_datum") + 1
    assert len(TRACK_CSVT.split(",")) == len(TRACK_CSV_COLUMNS)
    assert TRACK_CSVT.split(",")[TRACK_CSV_COLUMNS.index("mgrs")] == '"String"'
    refs = []
    for row in rows:
        lat, lon = float(row["latitude"]), float(row["longitude"])
        # the mgrs package's reference, independently
        assert row["mgrs"].replace(" ", "") == mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
        assert row["mgrs"].startswith("17T ")
        refs.append(row["mgrs"])
    assert len(set(refs)) == len(refs)  # 39 m apart: six different 1 m squares
    # GDAL reads it as a string column beside the point geometry
    path = tmp_path / "t.csv"
    path.write_text(buf.getvalue())
    (tmp_path / "t.csvt").write_text(TRACK_CSVT)
    meta, _, geoms, fields = pyogrio.raw.read(
        path, X_POSSIBLE_NAMES="longitude", Y_POSSIBLE_NAMES="latitude"
    )
    cols = dict(zip(meta["fields"], fields, strict=True))
    assert list(cols["mgrs"]) == refs
    assert geoms is not None and len(geoms) == 6


def test_without_geodetic_the_mgrs_column_is_empty():
    buf = io.StringIO()
    write_tracks_csv(buf, _tracks())
    rows = list(csv.DictReader(io.StringIO(buf.getvalue())))
    assert all(r["mgrs"] == "" for r in rows) and np.all([r["longitude"] == "" for r in rows])
