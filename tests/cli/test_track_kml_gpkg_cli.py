"""``demtrack track -o x.kml`` / ``-o x.gpkg`` pick the KML and GeoPackage writers."""

from __future__ import annotations

import sqlite3
from xml.etree import ElementTree as ET

import pytest

from demtrack.cli import main
from demtrack.core.io.track_io import GPKG_APPLICATION_ID, KML_NS

pytestmark = pytest.mark.timeout(900)


def test_track_writes_kml_and_geopackage(capsys, sample_site_dir, tmp_path):
    det = tmp_path / "dets.jsonl"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "passing-vehicles"]
    assert main([*argv, "-o", str(det)]) == 0
    counts = {}
    for suffix in (".kml", ".gpkg"):
        out = tmp_path / f"tracks{suffix}"
        argv = ["track", "--site", str(sample_site_dir), "--detections", str(det)]
        assert main([*argv, "--method", "kalman", "-o", str(out)]) == 0
        text = capsys.readouterr().out
        assert f"-> {out}" in text
        if suffix == ".kml":
            marks = ET.parse(out).getroot().iter(f"{{{KML_NS}}}Placemark")
            counts[suffix] = sum(1 for _ in marks)
            lon, lat, _ = (
                next(ET.parse(out).getroot().iter(f"{{{KML_NS}}}coordinates"))
                .text.split()[0]
                .split(",")
            )
            assert 40.3 < float(lat) < 40.4 and -79.7 < float(lon) < -79.5
        else:
            conn = sqlite3.connect(out)
            assert conn.execute("PRAGMA application_id").fetchone()[0] == GPKG_APPLICATION_ID
            counts[suffix] = conn.execute("SELECT COUNT(*) FROM tracks").fetchone()[0]
    assert counts[".kml"] == counts[".gpkg"] >= 2
