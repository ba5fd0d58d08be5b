"""The issue's bar: KML and GPX of the sample site (the real Bushy Run, EGM96) read by GDAL.

Every height GDAL reads from a KML ``absolute`` altitude or a GPX ``<ele>`` must be the
point's ellipsoidal height minus the EGM96 undulation there, within 0.1 m, where ``N`` is
read independently of PROJ (rasterio + numpy bilinear over Debian's ``egm96_15.gtx``,
:mod:`geoid_oracle`). Both the server's export functions (``/api/tracks/export``'s) and
one ``demtrack track`` run are checked; the GeoJSON of the same run keeps ellipsoidal z
(RFC 7946) and carries both heights with their names.
"""

from __future__ import annotations

import json

import numpy as np
import pyogrio
import pyogrio.raw
import pytest
import shapely
from geoid_oracle import EGM96_DEBIAN, egm96_n

from demtrack.cli import main
from demtrack.core.site.folder import load_site
from demtrack.server.site_info import elevation_at
from demtrack.server.track_export import export_bytes, site_heights, time_base

pytestmark = [
    pytest.mark.timeout(900),
    pytest.mark.skipif(not EGM96_DEBIAN.is_file(), reason="Debian's proj-data is needed"),
]


def _bodies(site):
    """Two stored-track bodies on the DEM surface, one with a gap, spread over the site."""
    rng = np.random.default_rng(0)
    bodies = []
    for tid, (e0, n0) in enumerate([(-120.0, -100.0), (60.0, 110.0)], start=1):
        t = np.arange(12) * 2.0
        e = e0 + 8.0 * t * (1 if tid == 1 else -0.5) + rng.normal(0, 0.5, t.size)
        n = n0 + 4.0 * t * (1 if tid == 1 else -1) + rng.normal(0, 0.5, t.size)
        u = site.dem.sample(e, n)
        lat, lon, h = site.frame.to_geodetic(e, n, u)
        pts = [
            {
                "t_s": float(t[k]), "e_m": float(e[k]), "n_m": float(n[k]), "u_m": float(u[k]),
                "lat_deg": float(lat[k]), "lon_deg": float(lon[k]), "h_m": float(h[k]),
                "sensors": ["cam1"], "detection_ids": [k],
            }
            for k in range(t.size)
        ]  # fmt: skip
        gaps = [[9.0, 13.0]] if tid == 1 else []
        bodies.append(
            {"id": tid, "cls": "vehicle", "points": pts, "sensors": ["cam1"], "gaps": gaps}
        )
    return bodies


def _gdal_points(path, layer=None):
    """(lon, lat, height) of every vertex GDAL reads from ``path``.

    KML: the geometry's z (the ``absolute`` altitude); GPX ``track_points``: GDAL gives
    2-D points and ``<ele>`` as the ``ele`` field.
    """
    meta, _, geoms, fields = pyogrio.raw.read(path, layer=layer)
    xyz = np.vstack([shapely.get_coordinates(shapely.from_wkb(g), include_z=True) for g in geoms])
    if layer == "track_points":
        xyz[:, 2] = fields[list(meta["fields"]).index("ele")]
    return xyz


def _assert_sea_level(xyz, lonlat_h):
    """Vertex k is point k (same lon/lat) and its height is h - N(EGM96) there (0.1 m)."""
    ref = np.asarray(lonlat_h, dtype=float)
    assert xyz.shape == ref.shape
    np.testing.assert_allclose(xyz[:, :2], ref[:, :2], atol=1e-9)
    h = ref[:, 2]
    want = h - egm96_n(xyz[:, 1], xyz[:, 0])
    err = np.abs(xyz[:, 2] - want)
    assert err.max() < 0.1, err.max()
    assert np.all(xyz[:, 2] - h > 33.0)  # not the ellipsoidal height: the geoid is 34 m down
    return float(err.max())


def test_server_exports_kml_and_gpx_are_above_egm96(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    assert site.geoid.name == "EGM96"
    bodies = _bodies(site)
    heights = site_heights(site)
    assert heights.orthometric and "EGM96" in heights.note
    ref = [(p["lon_deg"], p["lat_deg"], p["h_m"]) for b in bodies for p in b["points"]]
    for fmt, layer in (("kml", None), ("gpx", "track_points")):
        path = tmp_path / f"t.{fmt}"
        path.write_bytes(export_bytes(fmt, bodies, site.frame, time_base(None), heights))
        xyz = _gdal_points(path, layer)
        _assert_sea_level(xyz, ref)
        text = path.read_text()
        assert "orthometric" in text and "EGM96" in text  # the file says which height it is
    # GDAL's KML reader also sees the altitude's datum in the placemark's data.
    meta, _, _, fields = pyogrio.raw.read(tmp_path / "t.kml")
    alt = list(fields[list(meta["fields"]).index("altitude")])
    assert alt == ["orthometric, above the EGM96 geoid"] * 2
    # GeoJSON: z stays ellipsoidal, both heights are named properties.
    doc = json.loads(export_bytes("geojson", bodies, site.frame, time_base(None), heights))
    props = doc["features"][0]["properties"]
    assert props["elevation_datum"] == "EGM96 geoid"
    h = np.array(props["h_wgs84_m"])
    np.testing.assert_allclose(h, [p["h_m"] for p in bodies[0]["points"]])
    lat = [p["lat_deg"] for p in bodies[0]["points"]]
    lon = [p["lon_deg"] for p in bodies[0]["points"]]
    np.testing.assert_allclose(props["elevation_m"], h - egm96_n(lat, lon), atol=1e-3)


def test_readout_is_in_the_sites_datum(sample_site_dir):
    site = load_site(sample_site_dir)
    state = type("S", (), {"site": site})()
    ans = elevation_at(state, 10.0, -20.0)
    n = float(egm96_n(ans["lat_deg"], ans["lon_deg"]))
    assert ans["elevation_datum"] == "EGM96 geoid"
    assert ans["undulation_m"] == pytest.approx(n, abs=1e-3)
    assert ans["elevation_m"] == pytest.approx(ans["h_m"] - n, abs=1e-3)


def test_track_command_kml_and_gpx_are_above_egm96(sample_site_dir, tmp_path, capsys):
    det = tmp_path / "dets.jsonl"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "vehicle-run"]
    assert main([*argv, "-o", str(det)]) == 0
    base = ["track", "--site", str(sample_site_dir), "--detections", str(det)]
    for suffix in (".geojson", ".kml", ".gpx"):
        assert main([*base, "--method", "kalman", "-o", str(tmp_path / f"t{suffix}")]) == 0
    capsys.readouterr()
    doc = json.loads((tmp_path / "t.geojson").read_text())
    ref = [tuple(c) for f in doc["features"] for line in f["geometry"]["coordinates"] for c in line]
    assert len(ref) > 20
    worst = []
    for fmt, layer in (("kml", None), ("gpx", "track_points")):
        xyz = _gdal_points(tmp_path / f"t.{fmt}", layer)
        worst.append(_assert_sea_level(xyz, ref))
    assert max(worst) < 1e-3  # in fact: the same grid, the same bilinear rule
