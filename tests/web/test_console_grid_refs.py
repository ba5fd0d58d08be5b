"""MGRS and UTM in the console (issue 27, item 5), in Chromium: the cursor readout and the
geolocation table show the grid references of their points, checked against the ``mgrs``
package and pyproj."""

from __future__ import annotations

import math

import mgrs
import pytest
from pyproj import Transformer
from web_helpers import SHOTS, open_console

pytestmark = pytest.mark.timeout(300)


def _utm_text(lat, lon, zone, band):
    e, n = Transformer.from_crs(4326, 32600 + zone, always_xy=True).transform(lon, lat)
    return f"{zone:02d}{band} {math.floor(e):06d}E {math.floor(n):07d}N"


def test_readout_shows_mgrs_and_utm(page, fed_server):
    open_console(page, fed_server)
    box = page.locator("#map").bounding_box()
    x, y = int(box["x"] + box["width"] * 0.4), int(box["y"] + box["height"] * 0.5)
    page.mouse.move(x, y)
    page.wait_for_function("document.querySelector('#readout').textContent.includes('MGRS')")
    e, n = page.evaluate(
        f"window.demtrack.map.map.getCoordinateFromPixel([{x - box['x']}, {y - box['y']}])"
    )
    with fed_server.client() as c:
        ans = c.get("/api/site/elevation", params={"e": round(e, 2), "n": round(n, 2)}).json()
    lat, lon = ans["lat_deg"], ans["lon_deg"]
    theirs = mgrs.MGRS().toMGRS(lat, lon, MGRSPrecision=5)
    assert ans["mgrs"].replace(" ", "") == theirs
    assert ans["utm"] == _utm_text(lat, lon, int(theirs[:2]), theirs[2])
    text = page.locator("#readout").text_content()
    # a line of its own under the position and the height
    assert text.split("\n")[1] == f"MGRS {ans['mgrs']} · UTM {ans['utm']}"
    assert f"{lat:.6f}" in text and "elevation " in text  # beside lat/lon and the height
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.locator("#readout").screenshot(path=str(SHOTS / "readout_mgrs_utm.png"))
    assert page.record.errors == []


def test_geolocation_table_shows_each_hits_mgrs_and_utm(page, fed_server):
    open_console(page, fed_server)
    view = page.locator("#cam-cam1 .cam-view")
    view.scroll_into_view_if_needed()
    bb = view.bounding_box()
    page.mouse.click(
        round(bb["x"] + 720.5 / 1280 * bb["width"]), round(bb["y"] + 300.5 / 720 * bb["height"])
    )
    page.wait_for_selector("#geo-result tr.grid-ref")
    res = page.evaluate("window.demtrack.ui.geo.result")
    hits = res["hits"] + ([res["road"]] if res["road"] else [])
    cells = page.locator("#geo-result tr.grid-ref td").all_text_contents()
    assert len(cells) == len(hits) >= 1
    for h, cell in zip(hits, cells, strict=True):
        theirs = mgrs.MGRS().toMGRS(h["lat_deg"], h["lon_deg"], MGRSPrecision=5)
        assert h["mgrs"].replace(" ", "") == theirs
        utm = _utm_text(h["lat_deg"], h["lon_deg"], int(theirs[:2]), theirs[2])
        assert cell == f"MGRS {h['mgrs']}  ·  UTM {utm}"
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.locator("#geo-result").screenshot(path=str(SHOTS / "geolocation_mgrs_utm.png"))
    assert page.record.errors == []


def test_marker_list_shows_mgrs_and_utm(page, fed_server):
    open_console(page, fed_server)
    with fed_server.client() as c:
        r = c.post(
            "/api/markers", json={"t_s": 1_767_225_600.0, "name": "OP2", "e_m": 40.0, "n_m": 10.0}
        )
        assert r.status_code == 201, r.text
        m = r.json()
    page.wait_for_selector(f"#marker-list > div[data-marker='{m['id']}'] [data-utm]")
    row = page.locator(f"#marker-list > div[data-marker='{m['id']}']")
    assert row.locator("[data-mgrs]").text_content() == m["mgrs"]
    theirs = mgrs.MGRS().toMGRS(m["lat_deg"], m["lon_deg"], MGRSPrecision=5)
    utm = _utm_text(m["lat_deg"], m["lon_deg"], int(theirs[:2]), theirs[2])
    assert row.locator("[data-utm]").text_content() == f"UTM {utm}" == f"UTM {m['utm']}"
    SHOTS.mkdir(parents=True, exist_ok=True)
    row.screenshot(path=str(SHOTS / "marker_mgrs_utm.png"))
    assert page.record.errors == []
