"""The console's export menu downloads the server's files (one writer per format).

Chromium clicks "Export tracks" for every format in the menu; the page must ask
``/api/tracks/export`` and save its answer unchanged: the saved bytes equal what the same
request to the server returns (GeoPackage: the same layers and features, as GDAL stamps
``last_change`` with the time of writing). The tracks in the files are the page's
selection, at the API's positions.
"""

from __future__ import annotations

import io
import json
import zipfile
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np
import pyogrio
import pyogrio.raw
import pytest
from web_helpers import open_console, wait_until

pytestmark = pytest.mark.timeout(600)


def _api_tracks(server: Any) -> list[dict[str, Any]]:
    with server.client() as c:
        return c.get("/api/tracks").json()["tracks"]


def _click_export(page: Any, fmt: str) -> tuple[bytes, str, str]:
    """Choose ``fmt``, click Export: (saved bytes, suggested name, the export request URL)."""
    page.select_option("#export-format", fmt)
    with page.expect_request(lambda r: "/api/tracks/export" in r.url) as req:
        with page.expect_download() as info:
            page.locator("#export-tracks").click()
    data = open(info.value.path(), "rb").read()
    return data, info.value.suggested_filename, req.value.url


def _gpkg_content(path):
    out = {}
    for name, _ in pyogrio.list_layers(path):
        meta, _, geoms, fields = pyogrio.raw.read(path, layer=str(name))
        out[str(name)] = (list(meta["fields"]), list(geoms), [list(f) for f in fields])
    return out


def test_export_menu_offers_geopackage_and_downloads_the_servers_bytes(page, fed_server, tmp_path):
    open_console(page, fed_server)
    n_api = len(_api_tracks(fed_server))
    wait_until(lambda: page.evaluate("window.demtrack.store.tracks.size") >= n_api, page=page)
    options = page.eval_on_selector_all(
        "#export-format option", "os => os.map((o) => [o.value, o.textContent.trim()])"
    )
    assert ["gpkg", "GeoPackage"] in options and ["kmz", "KMZ"] in options
    formats = [v for v, _ in options]
    assert formats == ["geojson", "csv", "gpx", "kml", "kmz", "gpkg"]
    for fmt in formats:
        data, name, url = _click_export(page, fmt)
        assert name == f"demtrack-tracks.{fmt}"
        with fed_server.client() as c:
            r = c.get(url)  # the page's own request, asked again directly
        assert r.status_code == 200
        if fmt != "gpkg":
            assert data == r.content, fmt
        else:
            a, b = tmp_path / "page.gpkg", tmp_path / "server.gpkg"
            a.write_bytes(data)
            b.write_bytes(r.content)
            assert _gpkg_content(a) == _gpkg_content(b)
            assert pyogrio.read_info(a, layer="tracks")["capabilities"]["fast_spatial_filter"]
        if fmt == "kmz":
            with zipfile.ZipFile(io.BytesIO(data)) as zf:
                assert zf.namelist() == ["doc.kml"]
    assert page.record.errors == []


def test_exported_tracks_are_the_selection_at_the_api_positions(page, fed_server):
    open_console(page, fed_server)
    api = {t["id"]: t for t in _api_tracks(fed_server)}
    wait_until(lambda: page.evaluate("window.demtrack.store.tracks.size") >= len(api), page=page)
    data, _, url = _click_export(page, "geojson")
    q = parse_qs(urlsplit(url).query)
    doc = json.loads(data)
    ids = [f["properties"]["track_id"] for f in doc["features"]]
    assert ids == sorted(int(i) for i in q["track"])  # the page's selection, by id
    t_from = float(q["t_from"][0]) if "t_from" in q else -np.inf
    t_to = float(q["t_to"][0]) if "t_to" in q else np.inf
    for f in doc["features"]:
        body = api[f["properties"]["track_id"]]
        want = [p for p in body["points"] if t_from <= p["t_s"] <= t_to]
        got = [tuple(c) for line in f["geometry"]["coordinates"] for c in line]
        # RFC 7946 [lon, lat, h]; a one-point run is its point twice.
        assert set(got) == {(p["lon_deg"], p["lat_deg"], p["h_m"]) for p in want}
        assert f["properties"]["times_s"] == [p["t_s"] for p in want]
        assert all(-80 < c[0] < -79 and 40 < c[1] < 41 for c in got)
    # One track selected: the menu exports that track only.
    one = ids[0]
    page.evaluate(
        "async (id) => { const m = await import('/console/export.mjs');"
        " window.__u = m.tracksExportURL('gpx', [{id, points: []}]); }",
        one,
    )
    assert page.evaluate("window.__u") == f"/api/tracks/export?format=gpx&track={one}"
    assert page.record.errors == []
