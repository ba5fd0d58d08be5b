"""A marker's UTM beside its MGRS: stored, streamed, listed and in the CSV export."""

from __future__ import annotations

import csv
import io
import math

import mgrs
from pyproj import Transformer
from server_helpers import AUTH

T0 = 1_767_225_600.25


def test_marker_carries_utm_in_body_and_csv(client):
    r = client.post("/api/markers", headers=AUTH, json={"t_s": T0, "e_m": 120.0, "n_m": -35.5})
    assert r.status_code == 201, r.text
    m = r.json()
    lat, lon = m["lat_deg"], m["lon_deg"]
    ref = mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
    zone, band = int(ref[:2]), ref[2]
    e, n = Transformer.from_crs(4326, 32600 + zone, always_xy=True).transform(lon, lat)
    assert m["utm"] == f"{zone:02d}{band} {math.floor(e):06d}E {math.floor(n):07d}N"
    # the MGRS digits are the same metres
    assert m["mgrs"].endswith(f"{math.floor(e) % 100000:05d} {math.floor(n) % 100000:05d}")
    assert client.get("/api/markers", headers=AUTH).json()["markers"] == [m]
    text = client.get("/api/markers/export?format=csv", headers=AUTH).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows[0]["utm"] == m["utm"] and rows[0]["mgrs"] == m["mgrs"]
    assert list(rows[0]).index("utm") == list(rows[0]).index("mgrs") + 1
