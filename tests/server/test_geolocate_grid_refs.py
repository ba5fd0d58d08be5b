"""MGRS and UTM beside lat/lon in every geolocation answer (API and CLI), against the
``mgrs`` package and pyproj."""

from __future__ import annotations

import math

import mgrs
import pytest
from pyproj import Transformer
from server_helpers import AUTH

from demtrack.cli import main


def test_every_hit_carries_mgrs_and_utm(ro_client):
    r = ro_client.post(
        "/api/geolocate", headers=AUTH, json={"sensor": "cam1", "u": 640, "v": 500, "rule": "all"}
    )
    assert r.status_code == 200
    doc = r.json()
    hits = doc["hits"] + doc["selected"] + ([doc["road"]] if doc["road"] else [])
    assert len(hits) >= 2  # the hits and the selected ones
    for h in hits:
        lat, lon = h["lat_deg"], h["lon_deg"]
        theirs = mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
        assert h["mgrs"].replace(" ", "") == theirs
        u = h["utm"]
        assert u["epsg"] == 32600 + u["zone"] and u["hemisphere"] == "N"
        e, n = Transformer.from_crs(4326, u["epsg"], always_xy=True).transform(lon, lat)
        assert (u["easting_m"], u["northing_m"]) == pytest.approx((e, n), abs=1e-6)
        assert u["text"] == f"{u['zone']:02d}{u['band']} {math.floor(e):06d}E {math.floor(n):07d}N"
        # the MGRS digits are the UTM metres inside the 100 km square
        assert h["mgrs"].endswith(f"{math.floor(e) % 100000:05d} {math.floor(n) % 100000:05d}")


def test_cli_text_shows_mgrs(capsys, sample_site_dir):
    argv = [
        "geolocate",
        "--site",
        str(sample_site_dir),
        "--sensor",
        "cam1",
        "--pixel",
        "640",
        "500",
    ]
    assert main(argv) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "hit " in ln]
    assert lines and all(" | MGRS 17T " in ln for ln in lines)
