"""``demtrack track -o x.kml|x.gpkg|x.csv`` write with the server's writers, read back by GDAL."""

from __future__ import annotations

import shutil
import sqlite3
import subprocess
from xml.etree import ElementTree as ET

import pyogrio
import pytest

from demtrack.cli import main
from demtrack.core.io.track_io import GPKG_APPLICATION_ID, GX_NS, KML_NS, TRACK_CSVT

pytestmark = pytest.mark.timeout(900)


def test_track_writes_kml_geopackage_and_csv(capsys, sample_site_dir, tmp_path):
    det = tmp_path / "dets.jsonl"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "passing-vehicles"]
    # Real times from the scenario's start (before issue 27: track --epoch on session seconds)
    assert main([*argv, "--start", "2024-05-01T12:00:00Z", "-o", str(det)]) == 0
    counts = {}
    for suffix in (".kml", ".gpkg", ".csv"):
        out = tmp_path / f"tracks{suffix}"
        argv = ["track", "--site", str(sample_site_dir), "--detections", str(det)]
        assert main([*argv, "--method", "kalman", "-o", str(out)]) == 0
        text = capsys.readouterr().out
        assert f"-> {out}" in text
        if suffix == ".kml":
            root = ET.parse(out).getroot()
            counts[suffix] = sum(1 for _ in root.iter(f"{{{KML_NS}}}Placemark"))
            lon, lat, _ = next(root.iter(f"{{{GX_NS}}}coord")).text.split()
            assert 40.3 < float(lat) < 40.4 and -79.7 < float(lon) < -79.5
            when = next(root.iter(f"{{{KML_NS}}}when")).text
            assert when.startswith("2024-05-01T12:") and when.endswith("Z")
        elif suffix == ".gpkg":
            conn = sqlite3.connect(out)
            assert conn.execute("PRAGMA application_id").fetchone()[0] == GPKG_APPLICATION_ID
            conn.close()
            counts[suffix] = pyogrio.read_info(out, layer="tracks")["features"]
        else:
            csvt = out.with_suffix(".csvt")
            assert csvt.read_text() == TRACK_CSVT
            n_rows = len(out.read_text().splitlines()) - 1
            info = pyogrio.read_info(out, X_POSSIBLE_NAMES="longitude", Y_POSSIBLE_NAMES="latitude")
            assert info["features"] == n_rows and info["geometry_type"] == "Point"
            if shutil.which("ogrinfo"):
                so = subprocess.run(
                    [
                        "ogrinfo",
                        "-ro",
                        "-so",
                        "-oo",
                        "X_POSSIBLE_NAMES=longitude",
                        "-oo",
                        "Y_POSSIBLE_NAMES=latitude",
                        str(out),
                        "tracks",
                    ],
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
                # The .csvt gives the types: a DateTime time, Integer ids.
                assert "time_utc: DateTime" in so and "track_id: Integer" in so
    assert counts[".kml"] == counts[".gpkg"] >= 2
