"""Cursor readout and map navigation (issue 26, item 8), in Chromium.

The readout's elevation is the ground's height above the EGM96 geoid, named: the oracle
is PROJ's own EPSG:4979 -> EPSG:4326+5773 (WGS84 + EGM96 height) transformation of the
API's ellipsoidal height, with Debian's grid folder added, independent of the server's
grid pipeline. A home control brings the whole site back; after Follow, Esc gives the
map back the view it had.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from web_helpers import SHOTS, open_console, wait_until

pytestmark = pytest.mark.timeout(300)

GRID_DIR = Path("/usr/share/proj")


def egm96_height(lat_deg: float, lon_deg: float, h_m: float) -> float:
    import pyproj.datadir
    from pyproj import Transformer

    pyproj.datadir.append_data_dir(str(GRID_DIR))
    tr = Transformer.from_crs("EPSG:4979", "EPSG:4326+5773", always_xy=True, only_best=True)
    return float(tr.transform(lon_deg, lat_deg, h_m)[2])


def test_readout_shows_the_elevation_in_its_datum(page, fed_server):
    assert (GRID_DIR / "egm96_15.gtx").is_file(), "Debian's proj-data (egm96_15.gtx) is needed"
    open_console(page, fed_server)
    box = page.locator("#map").bounding_box()
    x, y = int(box["x"] + box["width"] * 0.45), int(box["y"] + box["height"] * 0.55)
    page.mouse.move(x, y)
    page.wait_for_function("document.querySelector('#readout').textContent.includes('elevation')")
    e, n = page.evaluate(
        f"window.demtrack.map.map.getCoordinateFromPixel([{x - box['x']}, {y - box['y']}])"
    )
    with fed_server.client() as c:
        ans = c.get("/api/site/elevation", params={"e": round(e, 2), "n": round(n, 2)}).json()
    want = egm96_height(ans["lat_deg"], ans["lon_deg"], ans["h_m"])
    assert ans["elevation_datum"] == "EGM96 geoid"
    assert ans["elevation_m"] == pytest.approx(want, abs=0.01)
    # On the sample site (Pennsylvania) the geoid lies about 34 m below the ellipsoid.
    assert ans["elevation_m"] - ans["h_m"] == pytest.approx(34.0, abs=1.0)
    text = page.locator("#readout").text_content()
    assert f"elevation {want:.1f} m (EGM96 geoid)" in text
    assert f"local up {ans['u_m']:.1f} m" in text
    assert "DEM " not in text  # the local-frame up is no longer called an elevation
    assert page.record.errors == []


def test_home_control_and_follow_then_esc_give_the_site_back(page, fed_server):
    open_console(page, fed_server)
    m = "window.demtrack.map"
    assert page.evaluate(f"{m}.siteInView()")
    start = page.evaluate(f"[{m}.view.getCenter(), {m}.view.getResolution()]")
    # Zoomed in and panned away: the home control shows the whole site again.
    page.evaluate(f"{m}.view.setResolution({m}.view.getResolution() / 8)")
    page.evaluate(f"{m}.view.setCenter([{m}.extent[0], {m}.extent[1]])")
    assert not page.evaluate(f"{m}.siteInView()")
    page.locator("#map-home").click()
    assert page.evaluate(f"{m}.siteInView()")
    np_start = page.evaluate(f"[{m}.view.getCenter(), {m}.view.getResolution()]")
    assert np_start == start
    # The Home key does the same.
    page.evaluate(f"{m}.view.setCenter([{m}.extent[2], {m}.extent[3]])")
    page.locator("#map").click(position={"x": 5, "y": 5})
    page.keyboard.press("Home")
    assert page.evaluate(f"{m}.siteInView()")
    # Follow a track, zoomed in on it; Esc brings back the view from before Follow.
    page.evaluate(f"{m}.view.setResolution({m}.view.getResolution() / 2)")
    before = page.evaluate(f"[{m}.view.getCenter(), {m}.view.getResolution()]")
    page.wait_for_selector("#track-list > div[data-track]")
    page.locator("#track-list > div[data-track]").first.click()
    page.locator("#follow-btn").click()
    wait_until(lambda: page.evaluate(f"{m}.view.getCenter()") != before[0], 10, page=page)
    page.evaluate(
        f"{m}.view.setResolution({m}.view.getResolution() / 4)"
    )  # zoomed in while following
    page.wait_for_timeout(300)
    assert page.evaluate(f"{m}.view.getCenter()") != before[0]
    page.keyboard.press("Escape")
    assert wait_until(
        lambda: page.evaluate(f"[{m}.view.getCenter(), {m}.view.getResolution()]") == before,
        10,
        page=page,
    ), page.evaluate(f"[{m}.view.getCenter(), {m}.view.getResolution()]")
    assert page.evaluate("window.demtrack.ui.following") is False
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "after_follow_esc.png"))
    assert re.search(r"⌂", page.locator("#map-home").text_content())
    assert page.record.errors == []


def test_elevation_datum_without_the_geoid_grid(monkeypatch):
    """No EGM96 grid installed: the site's stated undulation, else the ellipsoid, named."""
    from demtrack.server import site_info

    monkeypatch.setattr(site_info, "_egm96", lambda: None)
    assert site_info.orthometric(40.0, -79.0, 300.0, -34.0) == (
        334.0,
        "geoid of the site (N = -34 m, stated)",
    )
    assert site_info.orthometric(40.0, -79.0, 300.0, 0.0) == (
        300.0,
        "WGS84 ellipsoid (no geoid model)",
    )
