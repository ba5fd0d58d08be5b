"""Markers are stored on the server: kept on one console, seen by another, kept over a
reload, removed for everyone; each row shows the server's MGRS reference and UTC time."""

from __future__ import annotations

import re
from datetime import UTC, datetime

import mgrs
import pytest
from web_helpers import SHOTS, open_console, wait_until

pytestmark = pytest.mark.timeout(300)


def _rows(pg) -> list[dict]:
    return pg.evaluate(
        "[...document.querySelectorAll('#marker-list > div[data-marker]')].map(d => ({"
        " id: Number(d.dataset.marker), text: d.textContent,"
        " mgrs: d.querySelector('[data-mgrs]')?.textContent }))"
    )


def test_markers_are_shared_stored_and_removed_for_everyone(page, browser, server_factory):
    srv = server_factory("markers")
    open_console(page, srv)
    other_ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    other = other_ctx.new_page()
    errors: list[str] = []
    other.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    try:
        open_console(other, srv)
        # geolocate a camera pixel and keep the chosen hit
        view = page.locator("#cam-cam1 .cam-view")
        view.scroll_into_view_if_needed()
        bb = view.bounding_box()
        page.mouse.click(bb["x"] + 0.56 * bb["width"], bb["y"] + 0.6 * bb["height"])
        page.wait_for_selector("#geo-result")
        hit = page.evaluate("window.demtrack.ui.geo.result.selected[0]")
        t_shown = page.evaluate("window.demtrack.timeline.now()")
        page.locator("#keep-marker").click()
        page.wait_for_selector("#marker-form")
        page.fill("#marker-name", "gate")
        page.fill("#marker-note", "white van waiting")
        page.locator("#marker-save").click()
        with srv.client() as c:
            stored = wait_until(
                lambda: [m for m in c.get("/api/markers").json()["markers"] if m["name"] == "gate"],
                timeout_s=20,
            )
        (m,) = stored
        assert (m["e_m"], m["n_m"], m["u_m"]) == pytest.approx(
            (hit["e_m"], hit["n_m"], hit["u_m"]), abs=1e-9
        )
        assert m["note"] == "white van waiting" and m["source"]["sensor"] == "cam1"
        assert m["t_s"] == pytest.approx(t_shown, abs=1e-6)
        assert m["mgrs"].replace(" ", "") == mgrs.MGRS().toMGRS(
            m["lat_deg"], m["lon_deg"], MGRSPrecision=5
        )
        clock = datetime.fromtimestamp(m["t_s"], UTC).strftime("%H:%M:%S")
        for pg in (page, other):  # this console and the other one show the server's marker
            rows = wait_until(
                lambda pg=pg: [r for r in _rows(pg) if r["id"] == m["id"] and "gate" in r["text"]],
                timeout_s=20,
                page=pg,
            )
            assert rows[0]["mgrs"] == m["mgrs"]
            assert clock in rows[0]["text"] and "UTC" in rows[0]["text"]
            assert re.search(r"\d+\.\d{6}°, -?\d+\.\d{6}°", rows[0]["text"])
        on_map = other.evaluate(
            "window.demtrack.map.markers.getSource().getFeatures()"
            ".map(f => f.getGeometry().getCoordinates())"
        )
        assert on_map == [[m["e_m"], m["n_m"]]]
        other.screenshot(path=str(SHOTS / "markers_other_console.png"))
        # Export markers saves the server's file, byte for byte (GPX: heights above the geoid)
        other.select_option("#export-format", "gpx")
        with other.expect_download() as info:
            other.locator("#export-markers").click()
        dl = info.value
        assert dl.suggested_filename == "demtrack-markers.gpx"
        with srv.client() as c:
            want = c.get("/api/markers/export?format=gpx").content
        assert open(dl.path(), "rb").read() == want and b"<wpt" in want
        # a reload lists it again (from the server)
        page.reload()
        page.wait_for_selector("body[data-ready='1']")
        wait_until(lambda: [r["id"] for r in _rows(page)] == [m["id"]], timeout_s=20, page=page)
        # removed on the other console: gone here and on the server
        other.locator(f"#marker-list > div[data-marker='{m['id']}'] button").click()
        wait_until(lambda: _rows(page) == [], timeout_s=20, page=page)
        with srv.client() as c:
            assert c.get("/api/markers").json()["markers"] == []
        assert page.record.errors == [] and errors == []
    finally:
        other_ctx.close()
